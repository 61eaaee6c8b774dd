// `bench ipc` protocol over Runtime actors (runtime_actors.hpp): Blob messages loaned from the
// publisher (large payloads as a blob beside the message) and stamped right before publish.
#include "runtime_actors.hpp"

#include <tessera/messages/types.hpp>

#include <condition_variable>
#include <mutex>
#include <optional>

namespace tessera::app::ipc {

namespace {

/// Payloads from this size on are loaned as a blob (Publisher::loanWithBlob), as a producer
/// of large arrays would: written once, not zeroed first. Smaller ones are a plain Data field.
constexpr std::size_t kBlobFrom = 64 << 10;

/// A Blob message whose payload holds `bytes` (contents undefined until written).
Loan<msg::Blob> loanPayload(const Publisher<msg::Blob>& pub, std::size_t bytes) {
  if (bytes < kBlobFrom) {
    auto loan = pub.loan(bytes + 64);
    loan->initPayload(static_cast<unsigned>(bytes));
    return loan;
  }
  auto loan = pub.loanWithBlob(bytes);
  loan->adoptPayload(loan.blobData());
  return loan;
}

/// Where a loanPayload() message's payload bytes are written.
std::byte* payloadOf(Loan<msg::Blob>& loan) {
  if (!loan.blob().empty()) return loan.blob().data();
  return reinterpret_cast<std::byte*>(loan->getPayload().begin());
}

/// Answers pings on "ping" with pongs on "pong".
class Echo : public Actor {
 public:
  Echo(std::atomic<bool>& quit, const ShmTransport* transport, Fill fill)
      : quit_(quit), transport_(transport), fill_(fill) {}
  void configure(ActorContext& ctx) override {
    pong_ = ctx.advertise<msg::Blob>("pong");
    ctx.subscribe<msg::Blob>("ping", MailboxPolicy::reliable(128),
                             [this](const Message<msg::Blob>& m) { onPing(m); });
  }

 private:
  void onPing(const Message<msg::Blob>& m) {
    const Nanos taken = steadyNow();
    const Wire in = readWire(m->getPayload().begin());
    std::uint64_t copies = 0;
    if (transport_ != nullptr) {
      const auto s = transport_->stats();
      copies = s.copies + s.heap_fallbacks;
    }
    auto prepare = [this](std::size_t bytes) -> void* {
      if (!next_ || next_bytes_ != bytes) {
        next_.emplace(loanPayload(pong_, bytes));
        setHeader((*next_)->initHeader(), 0, "bench", pong_.nextSeq());
        fill_(payloadOf(*next_), bytes, Kind::kPong);
        next_bytes_ = bytes;
      }
      return payloadOf(*next_);
    };
    auto send = [this] {
      auto loan = std::move(*next_);
      next_.reset();
      loan->getHeader().setStampNs(readWire(payloadOf(loan)).stamp);
      pong_.publish(std::move(loan));
    };
    auto control = [this](Wire w) {
      auto loan = pong_.loan(kControlBytes + 64);
      w.bytes = kControlBytes;
      w.stamp = steadyNow();
      setHeader(loan->initHeader(), w.stamp, "bench", pong_.nextSeq());
      writeWire(loan->initPayload(kControlBytes).begin(), w);
      pong_.publish(std::move(loan));
    };
    if (!logic_.handle(in, taken, copies, prepare, send, control)) {
      quit_ = true;
      quit_.notify_all();
    }
  }

  std::atomic<bool>& quit_;
  const ShmTransport* transport_;
  Publisher<msg::Blob> pong_;
  std::optional<Loan<msg::Blob>> next_;
  std::size_t next_bytes_ = 0;
  PayloadFiller fill_;
  FollowerLogic logic_;
};

}  // namespace

/// Takes pongs on "pong" for the leader's thread: stamps, keeps the last one, counts.
class Catcher : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::Blob>("pong", MailboxPolicy::reliable(128),
                             [this](const Message<msg::Blob>& m) {
                               const Nanos taken = steadyNow();
                               const Wire w = readWire(m->getPayload().begin());
                               {
                                 std::lock_guard lock(mutex_);
                                 taken_ = taken;
                                 last_ = w;
                                 ++count_;
                               }
                               arrived_.notify_one();
                             });
  }
  /// Pong number `n` (1-based) once it arrived.
  std::optional<std::pair<Wire, Nanos>> arrived(std::int64_t n) const {
    std::lock_guard lock(mutex_);
    if (count_ < n) return std::nullopt;
    return std::pair{last_, taken_};
  }
  /// Waits for pong number `n` (1-based) and returns it.
  std::pair<Wire, Nanos> await(std::int64_t n) const {
    // Blocks rather than spins: the stamps are taken in the handler, and on 2 cores a spinning
    // leader would steal the CPU from the threads being measured. A condition variable, not
    // std::atomic<int64_t>::wait: libstdc++ waits on 64-bit atomics through a shared proxy
    // after spinning with sched_yield, which measured ~9 us slower per one-way hop here.
    std::unique_lock lock(mutex_);
    arrived_.wait(lock, [&] { return count_ >= n; });
    return {last_, taken_};
  }

 private:
  mutable std::mutex mutex_;
  mutable std::condition_variable arrived_;
  std::int64_t count_ = 0;
  Wire last_;
  Nanos taken_ = 0;
};

namespace {

class RuntimeLeader final : public LeaderLink {
 public:
  RuntimeLeader(Runtime& rt, Catcher& catcher, ShmTransport* transport, Fill fill)
      : pub_(rt.externalPublisher<msg::Blob>("ping")),
        catcher_(catcher),
        transport_(transport),
        fill_(fill) {}
  void build(std::size_t bytes, Kind kind, std::int64_t value) override {
    next_.emplace(loanPayload(pub_, bytes));
    setHeader((*next_)->initHeader(), 0, "bench", pub_.nextSeq());
    fill_(payloadOf(*next_), bytes, kind, value);
  }
  Nanos send() override {
    auto loan = std::move(*next_);
    next_.reset();
    void* p = payloadOf(loan);
    Wire w = readWire(p);
    w.stamp = steadyNow();
    writeWire(p, w);
    loan->getHeader().setStampNs(w.stamp);
    pub_.publish(std::move(loan));
    if (w.kind == Kind::kPing || w.kind == Kind::kPrepare || w.kind == Kind::kStreamEnd) {
      ++expected_;
    }
    return w.stamp;
  }
  std::pair<Wire, Nanos> receive() override {
    if (transport_ == nullptr) return catcher_.await(expected_);
    for (;;) {
      if (auto pong = catcher_.arrived(expected_)) return *pong;
      transport_->receiveHere(std::chrono::milliseconds(100));
    }
  }
  std::uint64_t copies() const override {
    if (transport_ == nullptr) return 0;
    const auto s = transport_->stats();
    return s.copies + s.heap_fallbacks;
  }

 private:
  Publisher<msg::Blob> pub_;
  Catcher& catcher_;
  ShmTransport* transport_;
  PayloadFiller fill_;
  std::optional<Loan<msg::Blob>> next_;
  std::int64_t expected_ = 0;
};

}  // namespace

RuntimeOptions benchRuntimeOptions(int threads) {
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = threads;
  ro.show_progress = false;
  return ro;
}

std::unique_ptr<Actor> makeEcho(std::atomic<bool>& quit, const ShmTransport* transport, Fill fill) {
  return std::make_unique<Echo>(quit, transport, fill);
}

Catcher& addCatcher(Runtime& rt) {
  return static_cast<Catcher&>(rt.add("catcher", std::make_unique<Catcher>()));
}

std::unique_ptr<LeaderLink> makeRuntimeLeader(Runtime& rt, Catcher& catcher,
                                              ShmTransport* transport, Fill fill) {
  return std::make_unique<RuntimeLeader>(rt, catcher, transport, fill);
}

}  // namespace tessera::app::ipc
