// `bench ipc` over raw iceoryx, the floor under our transport: untyped chunks loaned and
// published as they are (UntypedPublisher/UntypedSubscriber, a WaitSet to block on), no
// serialisation and no Runtime.
#include "transports.hpp"

#include <iceoryx_posh/popo/untyped_publisher.hpp>
#include <iceoryx_posh/popo/untyped_subscriber.hpp>
#include <iceoryx_posh/popo/wait_set.hpp>
#include <iceoryx_posh/runtime/posh_runtime.hpp>

#include <chrono>
#include <optional>
#include <stdexcept>
#include <thread>

namespace tessera::app::ipc {

using namespace std::chrono_literals;

namespace {

iox::capro::ServiceDescription rawService(const char* topic) {
  return {"tessera_bench_raw", iox::capro::IdString_t(iox::cxx::TruncateToCapacity, topic),
          "bytes"};
}

/// One end of the raw path: publisher on `out`, subscriber on `in` watched by a WaitSet.
class RawEnd {
 public:
  RawEnd(const char* out, const char* in, Fill fill) : fill_(fill) {
    iox::popo::PublisherOptions po;
    po.subscriberTooSlowPolicy = iox::popo::ConsumerTooSlowPolicy::WAIT_FOR_CONSUMER;
    publisher_.emplace(rawService(out), po);
    iox::popo::SubscriberOptions so;
    so.queueCapacity = 128;
    so.queueFullPolicy = iox::popo::QueueFullPolicy::BLOCK_PRODUCER;
    subscriber_.emplace(rawService(in), so);
    waitset_.attachState(*subscriber_, iox::popo::SubscriberState::HAS_DATA).or_else([](auto) {
      throw std::runtime_error("raw iceoryx: cannot attach the subscriber to a WaitSet");
    });
  }
  ~RawEnd() {
    if (next_ != nullptr) publisher_->release(next_);
  }

  void waitConnected(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (subscriber_->getSubscriptionState() != iox::SubscribeState::SUBSCRIBED ||
           !publisher_->hasSubscribers()) {
      if (std::chrono::steady_clock::now() > deadline) {
        throw std::runtime_error("raw iceoryx: the other end did not connect");
      }
      std::this_thread::sleep_for(2ms);
    }
  }

  /// A loaned chunk of `bytes` with its payload written (kept until published).
  void* prepare(std::size_t bytes, Kind kind, std::int64_t value = 0) {
    if (next_ != nullptr && next_bytes_ == bytes) return next_;
    if (next_ != nullptr) publisher_->release(next_);
    next_ = loan(bytes);
    next_bytes_ = bytes;
    fill_(next_, bytes, kind, value);
    return next_;
  }
  /// Builds and publishes a control message now, leaving the prepared chunk alone.
  void control(Wire w) {
    void* p = loan(kControlBytes);
    w.bytes = kControlBytes;
    w.stamp = steadyNow();
    writeWire(p, w);
    publisher_->publish(p);
  }
  /// The chunk prepare() returned last.
  void* current() const { return next_; }
  void publish() {
    publisher_->publish(next_);
    next_ = nullptr;
  }
  /// Blocks for the next chunk; calls f(wire, take time) and releases it.
  template <typename F>
  void take(F&& f) {
    for (;;) {
      auto r = subscriber_->take();
      if (!r.has_error()) {
        const Nanos taken = steadyNow();
        const Wire w = readWire(r.value());
        subscriber_->release(r.value());
        f(w, taken);
        return;
      }
      waitset_.wait();
    }
  }

 private:
  std::optional<iox::popo::UntypedPublisher> publisher_;
  std::optional<iox::popo::UntypedSubscriber> subscriber_;
  iox::popo::WaitSet<> waitset_;
  void* loan(std::size_t bytes) {
    auto r = publisher_->loan(static_cast<std::uint32_t>(bytes), alignof(Wire));
    if (r.has_error()) throw std::runtime_error("raw iceoryx: loan failed");
    return r.value();
  }

  PayloadFiller fill_;
  void* next_ = nullptr;
  std::size_t next_bytes_ = 0;
};

class RawLeader final : public LeaderLink {
 public:
  explicit RawLeader(Fill fill) : end_("ping", "pong", fill) { end_.waitConnected(10s); }
  void build(std::size_t bytes, Kind kind, std::int64_t value) override {
    end_.prepare(bytes, kind, value);
  }
  Nanos send() override {
    const Nanos stamp = stampWire(end_.current());
    end_.publish();
    return stamp;
  }
  std::pair<Wire, Nanos> receive() override {
    std::pair<Wire, Nanos> out;
    end_.take([&](const Wire& w, Nanos taken) { out = {w, taken}; });
    return out;
  }

 private:
  RawEnd end_;
};

}  // namespace

int rawFollower(Fill fill, int round) {
  const std::string name = roundName(kRawFollowerName, round);
  iox::runtime::PoshRuntime::initRuntime(iox::RuntimeName_t(iox::cxx::TruncateToCapacity, name));
  RawEnd end("pong", "ping", fill);
  end.waitConnected(10s);
  FollowerLogic logic;
  bool more = true;
  while (more) {
    end.take([&](const Wire& in, Nanos taken) {
      more = logic.handle(
          in, taken, 0, [&](std::size_t bytes) { return end.prepare(bytes, Kind::kPong); },
          [&] { end.publish(); }, [&](const Wire& w) { end.control(w); });
    });
  }
  return 0;
}

void rawLeader(const Options& o, TransportResult& out, int round) {
  const std::string name = roundName(kRawLeaderName, round);
  iox::runtime::PoshRuntime::initRuntime(iox::RuntimeName_t(iox::cxx::TruncateToCapacity, name));
  RawLeader link(o.fill);
  lead(link, o, out);
}

}  // namespace tessera::app::ipc
