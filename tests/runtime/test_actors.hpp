// Small actors used by the runtime tests.
#pragma once

#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

namespace tessera::test {

/// Publishes `count` Blob messages on "out", one per timer tick of `period`, then finishes.
class CountingSource : public Actor {
 public:
  CountingSource(int count, Nanos period, std::size_t payload = 8)
      : count_(count), period_(period), payload_(payload) {}
  void configure(ActorContext& ctx) override {
    ctx_ = &ctx;
    ctx.declareFiniteSource();
    out_ = ctx.advertise<msg::Blob>("out");
    ctx.addTimer(period_, [this] { tick(); });
  }
  void tick() {
    if (sent_ >= count_) return;
    auto loan = out_.loan(payload_);
    setHeader(loan->initHeader(), ctx_->now(), "test", out_.nextSeq());
    loan->initPayload(static_cast<unsigned>(payload_));
    out_.publish(std::move(loan));
    if (++sent_ == count_) ctx_->finished();
    ctx_->reportProgress(static_cast<double>(sent_) / count_);
  }
  int sent_ = 0;

 private:
  int count_;
  Nanos period_;
  std::size_t payload_;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::Blob> out_;
};

/// Records the seq and stamp of every Blob on "in"; optionally sleeps to be slow.
class Recorder : public Actor {
 public:
  explicit Recorder(MailboxPolicy policy, std::chrono::microseconds work = {})
      : policy_(policy), work_(work) {}
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::Blob>("in", policy_, [this](const Message<msg::Blob>& m) {
      if (work_.count() > 0) std::this_thread::sleep_for(work_);
      seqs.push_back(m->getHeader().getSeq());
      stamps.push_back(m->getHeader().getStampNs());
      addresses.push_back(m.storage()->address());
    });
  }
  void stop() override { seen_at_stop = seqs.size(); }
  std::vector<std::uint64_t> seqs;
  std::vector<Nanos> stamps;
  std::vector<const void*> addresses;
  std::size_t seen_at_stop = 0;

 private:
  MailboxPolicy policy_;
  std::chrono::microseconds work_;
};

}  // namespace tessera::test
