// tessera bench ipc: latency and throughput between two processes of one machine, in the shape
// of iceoryx's iceperf (a leader pings, a follower answers with a pong of the same size), for
//  * iceoryx      our shared-memory transport: one Runtime per process, Cap'n Proto msg::Blob
//                 messages built in loaned chunks (ShmTransport), actors on both ends;
//  * iceoryx_raw  raw iceoryx chunks (UntypedPublisher/UntypedSubscriber, WaitSet): the floor;
//  * uds          a Unix-domain stream socket, the full payload copied each way;
//  * inproc       the same two actors in one Runtime, no transport, for reference.
// RouDi is embedded in this process (RouDiHost); leader and follower are forked children, always
// reaped (and killed on error, timeout or Ctrl-C), so no process or shared memory outlives it.
//
// Latency: the leader asks the follower to build its pong and waits for the confirmation, builds
// its ping (application work, not latency), waits a gap so both sides are idle, then stamps
// steady_clock and publishes (gap 1 ms by default: a message after a quiet
// spell, as sensor data arrives; with --gap-us 100 on an idle VM raw iceoryx's two
// single-threaded processes answer in ~8 us while ours and the socket take ~20 us, on a VM
// loaded by other jobs all three are near 10 us). The follower stamps on take and sends the
// prebuilt pong, which carries the ping's one-way latency and its own stamp. So no payload is
// being written anywhere while a message is under way (writing MiBs slows this VM's wake-ups).
// --fill says what building writes: `first-use` (default; iceperf's method, under which the
// issue's reference figures were taken: raw iceoryx flat at every size) writes a buffer or chunk
// in full the first time it is used and afterwards only its header; `every` writes every
// payload in full, as a producer filling each image would. Writing MiBs before each message
// evicts the caches the next wake-up runs from (every zero-copy transport then slows with size,
// raw iceoryx too) and leaves the socket's source bytes hot for its copy: the two modes bracket
// what an application sees.
// CLOCK_MONOTONIC is system-wide, so stamps of two processes compare. The two directions are
// kept apart: the ping wakes a process idle since the gap, the pong one that has just sent, so
// they form two modes and a median over both pooled would land in either from run to run. The
// one-way p50 is the mean of the two medians; p99 is over both. Round trip is ping stamp to
// pong take. Streaming: the leader publishes 64 B messages as fast as it can for
// --stream-seconds on a reliable (blocking) path; the follower counts them and reports the count
// when told the end.
#include "bench_commands.hpp"
#include "bench_util.hpp"

#include <tessera/messages/types.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/runtime.hpp>
#include <tessera/shm/roudi_host.hpp>
#include <tessera/shm/shm_transport.hpp>

#include <iceoryx_posh/popo/untyped_publisher.hpp>
#include <iceoryx_posh/popo/untyped_subscriber.hpp>
#include <iceoryx_posh/popo/wait_set.hpp>
#include <iceoryx_posh/runtime/posh_runtime.hpp>

#include <nlohmann/json.hpp>

#include <signal.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <condition_variable>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <functional>
#include <iomanip>
#include <iostream>
#include <new>
#include <optional>
#include <set>
#include <stdexcept>

namespace tessera::app {

namespace {

using namespace std::chrono_literals;

constexpr std::array<std::size_t, 4> kSizes{64, std::size_t{4} << 10, std::size_t{1} << 20,
                                            std::size_t{4} << 20};
constexpr std::size_t kStreamBytes = 64;
// First exchanges of every size (cold chunks, page faults) are not counted.
constexpr int kWarmup = 5;
// iceoryx runtime names of the children; each round's get the round's number appended (a name
// is registered once per RouDi).
constexpr char kShmLeaderName[] = "tessera_bench_ipc_leader";
constexpr char kShmFollowerName[] = "tessera_bench_ipc_follower";
constexpr char kRawLeaderName[] = "tessera_bench_ipc_raw_leader";
constexpr char kRawFollowerName[] = "tessera_bench_ipc_raw_follower";
std::string roundName(const char* base, int round) {
  return std::string(base) + "_" + std::to_string(round);
}

/// What building a message writes (--fill).
enum class Fill {
  kFirstUse,  // a buffer in full when it is first used (its pages faulted in), then its header
  kEvery,     // every message's payload in full
};

struct Options {
  int samples = 1000;
  /// The process transports take turns in this many rounds (fresh processes each), so a
  /// change of the machine's state over the run (other load, a slower phase of the VM) affects
  /// all of them alike and their ratios stay meaningful.
  int rounds = 5;
  int gap_us = 1000;
  double stream_seconds = 1.0;
  Fill fill = Fill::kFirstUse;
  bool json = false;
};

const char* fillName(Fill f) {
  return f == Fill::kEvery ? "every" : "first-use";
}

// kPrepare asks the follower to build its next pong (of `value` bytes) and answer kReady, so
// that no payload is written on either side while a ping or pong is under way.
enum class Kind : std::uint32_t { kPing, kPong, kPrepare, kReady, kStream, kStreamEnd, kQuit };

/// First bytes of every payload, whatever the transport.
struct Wire {
  Nanos stamp = 0;  // sender's steady clock right before publish/send
  // pong: the ping's one-way latency [ns]; answer to kStreamEnd: messages counted; kPrepare:
  // size of the pong to build.
  std::int64_t value = 0;
  std::uint64_t copies = 0;  // pong: the follower's messages copied so far (ours only)
  std::uint32_t bytes = 0;   // payload size, this header included
  Kind kind = Kind::kPing;
};
static_assert(sizeof(Wire) <= kSizes[0]);

Wire readWire(const void* p) {
  Wire w;
  std::memcpy(&w, p, sizeof w);
  return w;
}

void writeWire(void* p, const Wire& w) {
  std::memcpy(p, &w, sizeof w);
}

/// Stamps the Wire at `p` with the steady clock now, as the last thing before sending it.
Nanos stampWire(void* p) {
  Wire w = readWire(p);
  w.stamp = steadyNow();
  writeWire(p, w);
  return w.stamp;
}

/// Writes payloads as --fill says; one per process side, as it remembers what it wrote.
class PayloadFiller {
 public:
  explicit PayloadFiller(Fill fill) : fill_(fill) {}
  /// Writes the `bytes` at `p` (in full when the mode asks for it) and their Wire header.
  void operator()(void* p, std::size_t bytes, Kind kind, std::int64_t value = 0) {
    if (fill_ == Fill::kEvery || written_.insert({p, bytes}).second) std::memset(p, 0x5a, bytes);
    Wire w;
    w.bytes = static_cast<std::uint32_t>(bytes);
    w.kind = kind;
    w.value = value;
    writeWire(p, w);
  }

 private:
  Fill fill_;
  std::set<std::pair<const void*, std::size_t>> written_;  // first-use: buffers written in full
};

/// Small control messages (kPrepare, kReady, stream counts).
constexpr std::size_t kControlBytes = 64;

// ------------------------------------------------------------------ results

/// One-way figures keep the two directions apart before combining them: the ping wakes a
/// process idle since the gap, the pong one that has just sent, so their latencies form two
/// modes and a median over both pooled lands in either, run to run.
struct SizeResult {
  double p50_us = 0;       // mean of the ping and pong medians
  double ping_p50_us = 0;  // leader -> follower, after the idle gap
  double pong_p50_us = 0;  // follower -> leader, the answer
  double p99_us = 0;       // over every hop of both directions
  double rtt_p50_us = 0, rtt_p99_us = 0;
  std::uint64_t copies = 0;
};

/// Most ping-pongs per size one round records (--samples / --rounds).
constexpr int kMaxRoundSamples = 5000;

/// One round's samples of one payload size.
struct RoundSamples {
  std::array<float, 2 * kMaxRoundSamples> one_way{};  // [us], both directions of each exchange
  std::array<float, kMaxRoundSamples> round_trip{};   // [us]
  int count = 0;                                      // exchanges recorded
  std::uint64_t copies = 0;
};

/// What the leader measured in one round; lives in memory shared with the bench process.
struct TransportResult {
  std::array<RoundSamples, kSizes.size()> sizes{};
  std::int64_t streamed = 0;  // 64 B messages the follower counted while streaming
  double stream_s = 0;        // [s] from the first streamed message to the follower's count
  bool complete = false;
  std::array<char, 256> leader_error{}, follower_error{};  // what ended a child, if anything
};

void setError(std::array<char, 256>& error, const std::string& what) {
  std::snprintf(error.data(), error.size(), "%s", what.c_str());
}

/// A TransportResult in an anonymous shared mapping (inherited by forked children, no file).
class SharedResult {
 public:
  SharedResult() {
    void* p = ::mmap(nullptr, sizeof(TransportResult), PROT_READ | PROT_WRITE,
                     MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::runtime_error("bench ipc: mmap failed");
    result_ = new (p) TransportResult();
  }
  ~SharedResult() { ::munmap(result_, sizeof(TransportResult)); }
  SharedResult(const SharedResult&) = delete;
  SharedResult& operator=(const SharedResult&) = delete;
  TransportResult& get() { return *result_; }

 private:
  TransportResult* result_;
};

// ------------------------------------------------------------------ the leader's measurement

/// Leader side of one transport: build() is application work, send() stamps and publishes the
/// built message, receive() blocks until the next pong and returns it with its take time.
class LeaderLink {
 public:
  virtual ~LeaderLink() = default;
  virtual void build(std::size_t bytes, Kind kind, std::int64_t value = 0) = 0;
  virtual Nanos send() = 0;
  virtual std::pair<Wire, Nanos> receive() = 0;
  /// Messages this process copied so far (zero-copy transports that fell back to a copy).
  virtual std::uint64_t copies() const { return 0; }
};

/// One ping-pong of `bytes`; adds its one-way (both directions) and round-trip samples unless
/// warming up, and the messages either side copied to `copies`.
void pingPong(LeaderLink& link, std::size_t bytes, const Options& o, bool record,
              RoundSamples& samples, std::uint64_t& follower_copies) {
  const std::uint64_t own_copies = link.copies();
  link.build(kControlBytes, Kind::kPrepare, static_cast<std::int64_t>(bytes));
  link.send();
  if (link.receive().first.kind != Kind::kReady) {
    throw std::runtime_error("leader: the follower did not confirm its pong was ready");
  }
  link.build(bytes, Kind::kPing);
  std::this_thread::sleep_for(std::chrono::microseconds(o.gap_us));
  // The payload's stores are done before the stamp (large memsets may use non-temporal
  // stores that would otherwise drain inside the publish call and count as delivery).
  std::atomic_thread_fence(std::memory_order_seq_cst);
  const Nanos sent = link.send();
  const auto [pong, taken] = link.receive();
  if (pong.kind != Kind::kPong || pong.bytes != bytes) {
    throw std::runtime_error("leader: unexpected answer (kind " +
                             std::to_string(static_cast<int>(pong.kind)) + ", " +
                             std::to_string(pong.bytes) + " bytes)");
  }
  samples.copies += (link.copies() - own_copies) + (pong.copies - follower_copies);
  follower_copies = pong.copies;
  if (!record) return;
  const auto n = static_cast<std::size_t>(samples.count++);
  samples.one_way[2 * n] = static_cast<float>(static_cast<double>(pong.value) * 1e-3);
  samples.one_way[2 * n + 1] = static_cast<float>(static_cast<double>(taken - pong.stamp) * 1e-3);
  samples.round_trip[n] = static_cast<float>(static_cast<double>(taken - sent) * 1e-3);
}

/// One round: `o.samples` ping-pongs per size, then `o.stream_seconds` of streaming.
void lead(LeaderLink& link, const Options& o, TransportResult& out) {
  if (o.samples > kMaxRoundSamples) throw std::logic_error("bench ipc: round too long");
  // Sizes take turns, so a drift of the machine over the run (other load, a slower phase of
  // the VM) affects every size alike and the size ratios stay meaningful.
  std::uint64_t follower_copies = 0;
  for (int i = 0; i < o.samples + kWarmup; ++i) {
    for (std::size_t k = 0; k < kSizes.size(); ++k) {
      pingPong(link, kSizes[k], o, i >= kWarmup, out.sizes[k], follower_copies);
    }
  }

  // Streaming: as fast as the blocking path takes them, then the count from the follower.
  std::int64_t sent = 0;
  const Nanos start = steadyNow();
  const auto budget = static_cast<Nanos>(o.stream_seconds * 1e9);
  while (steadyNow() - start < budget) {
    for (int k = 0; k < 64; ++k, ++sent) {
      link.build(kStreamBytes, Kind::kStream);
      link.send();
    }
  }
  link.build(kControlBytes, Kind::kStreamEnd);
  link.send();
  const auto [count, taken] = link.receive();
  if (count.kind != Kind::kReady || count.value != sent) {
    throw std::runtime_error("leader: follower counted " + std::to_string(count.value) + " of " +
                             std::to_string(sent) + " streamed messages");
  }
  out.streamed = sent;
  out.stream_s = static_cast<double>(taken - start) * 1e-9;
  link.build(kControlBytes, Kind::kQuit);
  link.send();
  out.complete = true;
}

/// The follower's answer to one message: the prebuilt pong for a ping, a pong built (kPrepare)
/// or the stream count (kStreamEnd) confirmed by a control message. Returns false on quit.
/// prepare(bytes) returns the pong slot, built if it is not of `bytes`; send() publishes the
/// slot; control(wire) builds and sends a small message at once.
class FollowerLogic {
 public:
  template <typename Prepare, typename Send, typename Control>
  bool handle(const Wire& in, Nanos taken, std::uint64_t copies, Prepare&& prepare, Send&& send,
              Control&& control) {
    Wire answer;
    answer.kind = Kind::kReady;
    switch (in.kind) {
      case Kind::kPing: {
        void* p = prepare(in.bytes);
        Wire w = readWire(p);
        w.value = taken - in.stamp;
        w.copies = copies;
        w.kind = Kind::kPong;
        w.stamp = steadyNow();
        writeWire(p, w);
        send();
        return true;
      }
      case Kind::kPrepare:
        prepare(static_cast<std::size_t>(in.value));
        control(answer);
        return true;
      case Kind::kStream:
        ++streamed_;
        return true;
      case Kind::kStreamEnd:
        answer.value = streamed_;
        streamed_ = 0;
        control(answer);
        return true;
      default:
        return false;
    }
  }

 private:
  std::int64_t streamed_ = 0;
};

// ------------------------------------------------------------------ Runtime actors (iceoryx,
// inproc)

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

class RuntimeLeader final : public LeaderLink {
 public:
  /// With a transport, pongs are received on the calling thread (ShmTransport::receiveHere), as
  /// raw iceoryx's leader does: the thread that sent the ping is the one its pong wakes.
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

RuntimeOptions benchRuntimeOptions(int threads) {
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = threads;
  ro.show_progress = false;
  return ro;
}

ShmTopic blobTopic(const std::string& name, bool exported) {
  ShmTopic t;
  t.name = name;
  t.type = messageTypeOf<msg::Blob>();
  t.exported = exported;
  t.imported = !exported;
  t.importing_processes = 1;
  t.any_reliable = true;
  t.import_policy = MailboxPolicy::reliable(128);
  return t;
}

ShmTransportOptions shmOptions(const std::string& name, std::uint32_t index,
                               std::size_t max_chunk) {
  ShmTransportOptions so;
  so.runtime_name = name;
  so.process_index = index;
  so.max_chunk_bytes = max_chunk;
  return so;
}

int shmFollower(std::size_t max_chunk, Fill fill, int round) {
  ShmTransport transport(shmOptions(roundName(kShmFollowerName, round), 1, max_chunk));
  Runtime rt(benchRuntimeOptions(1));
  std::atomic<bool> quit{false};
  rt.add("echo", std::make_unique<Echo>(quit, &transport, fill));
  transport.attach(rt, {blobTopic("ping", false), blobTopic("pong", true)});
  rt.configure();
  rt.start();
  transport.startReceiving();
  if (!transport.waitForPublishers(10s)) throw std::runtime_error("follower: no leader");
  // Blocks rather than polls: a thread waking every millisecond is a third party to every
  // wake-up being measured.
  quit.wait(false);
  transport.stopReceiving();
  rt.stop();
  return 0;
}

void shmLeader(std::size_t max_chunk, const Options& o, TransportResult& out, int round) {
  ShmTransport transport(shmOptions(roundName(kShmLeaderName, round), 0, max_chunk));
  Runtime rt(benchRuntimeOptions(1));
  auto& catcher = static_cast<Catcher&>(rt.add("catcher", std::make_unique<Catcher>()));
  transport.attach(rt, {blobTopic("ping", true), blobTopic("pong", false)});
  RuntimeLeader link(rt, catcher, &transport, o.fill);
  rt.configure();
  rt.start();
  if (!transport.waitForPublishers(10s)) throw std::runtime_error("leader: no follower");
  lead(link, o, out);
  rt.stop();
}

void inprocRun(const Options& o, TransportResult& out) {
  Runtime rt(benchRuntimeOptions(2));
  std::atomic<bool> quit{false};
  rt.add("echo", std::make_unique<Echo>(quit, nullptr, o.fill));
  auto& catcher = static_cast<Catcher&>(rt.add("catcher", std::make_unique<Catcher>()));
  RuntimeLeader link(rt, catcher, nullptr, o.fill);
  rt.configure();
  rt.start();
  lead(link, o, out);
  rt.stop();
}

// ------------------------------------------------------------------ raw iceoryx

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

// ------------------------------------------------------------------ Unix-domain socket

void writeAll(int fd, const std::byte* p, std::size_t n) {
  while (n > 0) {
    const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) throw std::runtime_error(std::string("uds: send failed: ") + std::strerror(errno));
    p += w;
    n -= static_cast<std::size_t>(w);
  }
}

/// Buffered reading of length-framed messages from a stream socket (as a socket transport
/// would): one recv() may bring several small messages; a large one is copied out in pieces.
class UdsReader {
 public:
  explicit UdsReader(int fd) : fd_(fd), buffer_(kSizes.back() + (std::size_t{1} << 16)) {}
  /// Returns the next whole message's header and the time its last byte arrived.
  std::pair<Wire, Nanos> next() {
    fill(sizeof(Wire));
    const Wire w = readWire(buffer_.data() + begin_);
    if (w.bytes < sizeof(Wire) || w.bytes > kSizes.back()) {
      throw std::runtime_error("uds: bad frame of " + std::to_string(w.bytes) + " bytes");
    }
    fill(w.bytes);
    const Nanos taken = steadyNow();
    begin_ += w.bytes;
    return {w, taken};
  }

 private:
  void fill(std::size_t n) {
    if (end_ - begin_ >= n) return;
    if (begin_ + n > buffer_.size()) {  // compact
      std::memmove(buffer_.data(), buffer_.data() + begin_, end_ - begin_);
      end_ -= begin_;
      begin_ = 0;
    }
    while (end_ - begin_ < n) {
      const ssize_t r = ::recv(fd_, buffer_.data() + end_, buffer_.size() - end_, 0);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) throw std::runtime_error("uds: the other end closed the socket");
      end_ += static_cast<std::size_t>(r);
    }
  }
  int fd_;
  std::vector<std::byte> buffer_;
  std::size_t begin_ = 0, end_ = 0;
};

/// A message buffer written in advance and sent whole.
class UdsSender {
 public:
  UdsSender(int fd, Fill fill) : fd_(fd), buffer_(kSizes.back()), fill_(fill) {}
  void* prepare(std::size_t bytes, Kind kind, std::int64_t value = 0) {
    if (bytes_ != bytes) {
      fill_(buffer_.data(), bytes, kind, value);
      bytes_ = bytes;
    }
    return buffer_.data();
  }
  /// Sends a control message now, leaving the prepared buffer alone.
  void control(Wire w) {
    std::array<std::byte, kControlBytes> small{};
    w.bytes = kControlBytes;
    w.stamp = steadyNow();
    writeWire(small.data(), w);
    writeAll(fd_, small.data(), small.size());
  }
  void* current() { return buffer_.data(); }
  void send() {
    writeAll(fd_, buffer_.data(), bytes_);
    bytes_ = 0;  // built again next time, as --fill says
  }

 private:
  int fd_;
  std::vector<std::byte> buffer_;
  PayloadFiller fill_;
  std::size_t bytes_ = 0;
};

class UdsLeader final : public LeaderLink {
 public:
  UdsLeader(int fd, Fill fill) : sender_(fd, fill), reader_(fd) {}
  void build(std::size_t bytes, Kind kind, std::int64_t value) override {
    sender_.prepare(bytes, kind, value);
  }
  Nanos send() override {
    const Nanos stamp = stampWire(sender_.current());
    sender_.send();
    return stamp;
  }
  std::pair<Wire, Nanos> receive() override { return reader_.next(); }

 private:
  UdsSender sender_;
  UdsReader reader_;
};

int udsFollower(int fd, Fill fill) {
  UdsSender sender(fd, fill);
  UdsReader reader(fd);
  FollowerLogic logic;
  for (;;) {
    const auto [in, taken] = reader.next();
    const bool more = logic.handle(
        in, taken, 0, [&](std::size_t bytes) { return sender.prepare(bytes, Kind::kPong); },
        [&] { sender.send(); }, [&](const Wire& w) { sender.control(w); });
    if (!more) return 0;
  }
}

// ------------------------------------------------------------------ child processes

volatile std::sig_atomic_t g_interrupted = 0;

extern "C" void onInterrupt(int) {
  g_interrupted = 1;
}

/// Catches Ctrl-C / SIGTERM while the bench runs so children are killed and RouDi's shared
/// memory removed by destructors instead of being left behind; restores the old handlers.
class InterruptGuard {
 public:
  InterruptGuard() {
    g_interrupted = 0;
    struct sigaction sa {};
    sa.sa_handler = onInterrupt;
    sigemptyset(&sa.sa_mask);
    ::sigaction(SIGINT, &sa, &old_int_);
    ::sigaction(SIGTERM, &sa, &old_term_);
  }
  ~InterruptGuard() {
    ::sigaction(SIGINT, &old_int_, nullptr);
    ::sigaction(SIGTERM, &old_term_, nullptr);
  }
  static void check() {
    if (g_interrupted != 0) throw std::runtime_error("bench ipc: interrupted");
  }

 private:
  struct sigaction old_int_ = {};
  struct sigaction old_term_ = {};
};

/// Leader and follower of one transport. Destruction kills and reaps whatever still runs.
class Pair {
 public:
  ~Pair() {
    for (pid_t pid : running_) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, nullptr, 0);
    }
  }

  /// Forks a child running `body`; it exits 0 on success, 1 with the message in `error` on an
  /// exception, and dies with this process.
  void spawn(const std::function<int()>& body, std::array<char, 256>& error) {
    const pid_t parent = ::getpid();
    std::fflush(nullptr);
    const pid_t pid = ::fork();
    if (pid < 0) throw std::runtime_error("bench ipc: fork failed");
    if (pid == 0) {
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (::getppid() != parent) ::_exit(1);
      ::signal(SIGINT, SIG_DFL);
      ::signal(SIGTERM, SIG_DFL);
      int code = 1;
      try {
        code = body();
      } catch (const std::exception& e) {
        setError(error, e.what());
      }
      std::fflush(nullptr);
      ::_exit(code);  // no static destructors: they belong to the parent's state
    }
    running_.push_back(pid);
  }

  /// Waits for both; on a failure, a timeout or an interrupt the other one is killed. Returns
  /// "" on success, else why it failed.
  std::string wait(std::chrono::seconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    std::string failure;
    while (!running_.empty()) {
      pid_t pid = 0;
      int status = 0;
      for (pid_t p : running_) {
        if (::waitpid(p, &status, WNOHANG) == p) {
          pid = p;
          break;
        }
      }
      if (pid > 0) {
        running_.erase(std::remove(running_.begin(), running_.end(), pid), running_.end());
        const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
        if (!ok && failure.empty()) {
          failure = WIFSIGNALED(status)
                        ? "a child process died of signal " + std::to_string(WTERMSIG(status))
                        : "a child process failed";
        }
      } else if (failure.empty() && g_interrupted != 0) {
        failure = "interrupted";
      } else if (failure.empty() && std::chrono::steady_clock::now() > deadline) {
        failure = "timed out";
      } else {
        std::this_thread::sleep_for(2ms);
      }
      if (!failure.empty()) {
        for (pid_t p : running_) ::kill(p, SIGKILL);
      }
    }
    return failure;
  }

 private:
  std::vector<pid_t> running_;
};

/// iceoryx leaves the socket /tmp/NAME and the lock /tmp/NAME.lock of a runtime whose process
/// did not deregister (the children _exit, or were killed); removed when this goes, after the
/// children are reaped.
class RuntimeFiles {
 public:
  explicit RuntimeFiles(std::vector<std::string> names) : names_(std::move(names)) {}
  ~RuntimeFiles() {
    namespace fs = std::filesystem;
    for (const auto& name : names_) {
      std::error_code ec;
      const fs::path socket = fs::path("/tmp") / name;
      if (fs::is_socket(fs::symlink_status(socket, ec))) fs::remove(socket, ec);
      fs::remove(fs::path("/tmp") / (name + ".lock"), ec);
    }
  }
  RuntimeFiles(const RuntimeFiles&) = delete;
  RuntimeFiles& operator=(const RuntimeFiles&) = delete;

 private:
  std::vector<std::string> names_;
};

/// Leader and follower of one transport, forked when this is built and held at a gate until
/// run(). The iceoryx pairs are built before RouDi starts, while this process has one thread:
/// a child forked from a process whose other threads (RouDi's) may hold a lock at that moment
/// can deadlock on it.
class PairRun {
 public:
  /// `runtimes`: the iceoryx runtime names the children register.
  PairRun(std::string name, const std::function<void(TransportResult&)>& leader,
          const std::function<int()>& follower, std::vector<std::string> runtimes = {})
      : name_(std::move(name)), files_(std::move(runtimes)) {
    if (::pipe(gate_) != 0) throw std::runtime_error("bench ipc: pipe failed");
    auto gated = [this](std::function<int()> body) {
      return [this, body] {
        ::close(gate_[1]);
        char go = 0;
        if (::read(gate_[0], &go, 1) != 1) return 1;  // the bench gave up before starting
        ::close(gate_[0]);
        setIceoryxLogLevel("error");  // as RouDiHost sets it, after these were forked
        return body();
      };
    };
    pair_.spawn(gated(follower), shared_.get().follower_error);
    pair_.spawn(gated([this, leader] {
                  leader(shared_.get());
                  return 0;
                }),
                shared_.get().leader_error);
    ::close(gate_[0]);
    gate_[0] = -1;
  }
  ~PairRun() { closeGate(); }
  PairRun(const PairRun&) = delete;
  PairRun& operator=(const PairRun&) = delete;

  /// Lets both children start, waits for them and returns the leader's result (valid while
  /// this lives).
  const TransportResult& run(const Options& o) {
    const char go[2] = {1, 1};
    if (::write(gate_[1], go, sizeof go) != static_cast<ssize_t>(sizeof go)) {
      throw std::runtime_error("bench ipc: " + name_ + ": cannot start the children");
    }
    closeGate();
    // Generous: a sample takes a gap plus at most a few ms even at 4 MiB over the socket.
    const auto timeout =
        std::chrono::seconds(60 + static_cast<long>(o.samples) * static_cast<long>(kSizes.size()) *
                                      (o.gap_us + 10000) / 1000000);
    const std::string failure = pair_.wait(timeout);
    InterruptGuard::check();
    const TransportResult& r = shared_.get();
    if (!failure.empty() || !r.complete) {
      throw std::runtime_error(
          "bench ipc: " + name_ + ": " +
          (r.leader_error[0] != '\0' ? std::string(r.leader_error.data()) : failure) +
          (r.follower_error[0] != '\0' ? "; " + std::string(r.follower_error.data()) : ""));
    }
    return r;
  }

 private:
  void closeGate() {
    if (gate_[1] >= 0) ::close(gate_[1]);
    gate_[1] = -1;
  }

  std::string name_;
  SharedResult shared_;
  RuntimeFiles files_;  // destroyed after `pair_` reaped the children
  Pair pair_;
  int gate_[2] = {-1, -1};
};

/// Redirects this process's stdout (and its children's) to stderr while it lives.
class StdoutToStderr {
 public:
  StdoutToStderr() {
    std::cout.flush();
    std::fflush(stdout);
    saved_ = ::dup(STDOUT_FILENO);
    if (saved_ >= 0) ::dup2(STDERR_FILENO, STDOUT_FILENO);
  }
  ~StdoutToStderr() {
    std::cout.flush();
    std::fflush(stdout);
    if (saved_ >= 0) {
      ::dup2(saved_, STDOUT_FILENO);
      ::close(saved_);
    }
  }
  StdoutToStderr(const StdoutToStderr&) = delete;
  StdoutToStderr& operator=(const StdoutToStderr&) = delete;

 private:
  int saved_ = -1;
};

std::vector<MemPool> benchPools() {
  std::vector<ChunkDemand> demands;
  for (std::size_t bytes : kSizes) {
    demands.push_back({bytes, 8});  // raw chunks
    // Cap'n Proto Blob loans: the payload in the message, or beside it (loanWithBlob) after
    // a first segment of the default size.
    demands.push_back({bytes + kShmDefaultMessageBytes + 1024 + 2 * kShmChunkOverhead, 8});
  }
  // Streaming: subscriber queues and mailboxes full of small messages on both paths.
  demands.push_back({kShmDefaultMessageBytes + 1024 + kShmChunkOverhead, 512});
  demands.push_back({kStreamBytes, 512});
  return memPoolsFor(demands);
}

// ------------------------------------------------------------------ report

struct Row {
  std::string transport;
  std::size_t payload = 0;
  SizeResult r;
  std::optional<double> msgs_per_s;
  bool has_copies = false;
};

struct Target {
  std::string name, description;
  double value = 0, limit = 0;
  bool at_most = true;      // value <= limit, else value >= limit
  std::size_t payload = 0;  // the size the value was taken at, when one of several
  bool met() const { return at_most ? value <= limit : value >= limit; }
};

std::vector<Target> evaluate(const std::vector<Row>& rows) {
  auto find = [&](const std::string& transport, std::size_t payload) -> const Row& {
    for (const auto& r : rows)
      if (r.transport == transport && r.payload == payload) return r;
    throw std::logic_error("bench ipc: missing row");
  };
  // The largest ours / raw ratio of `field` over the sizes, and the size it is at.
  auto worstOverRaw = [&](double SizeResult::*field) {
    std::pair<double, std::size_t> worst{0.0, 0};
    for (std::size_t bytes : kSizes) {
      const double ratio = find("iceoryx", bytes).r.*field / find("iceoryx_raw", bytes).r.*field;
      if (ratio > worst.first) worst = {ratio, bytes};
    }
    return worst;
  };
  std::vector<Target> t;
  const auto [worst, worst_at] = worstOverRaw(&SizeResult::p50_us);
  t.push_back({"iceoryx_over_raw_p50_worst",
               "one-way p50, ours / raw iceoryx, worst at " + std::to_string(worst_at) + " B",
               worst, 1.5, true, worst_at});
  const double flat =
      find("iceoryx", kSizes.back()).r.p50_us / find("iceoryx", kSizes.front()).r.p50_us;
  t.push_back({"iceoryx_p50_4MiB_over_64B", "one-way p50, ours, 4 MiB / 64 B", flat, 1.3, true});
  t.push_back({"uds_over_iceoryx_p50_1MiB", "one-way p50 at 1 MiB, Unix socket / ours",
               find("uds", kSizes[2]).r.p50_us / find("iceoryx", kSizes[2]).r.p50_us, 25, false});
  t.push_back({"uds_over_iceoryx_p50_4MiB", "one-way p50 at 4 MiB, Unix socket / ours",
               find("uds", kSizes[3]).r.p50_us / find("iceoryx", kSizes[3]).r.p50_us, 100, false});
  // The same ratios on round trips, the figure iceperf reports (and the reference
  // figures are): a round trip adds both directions, whose wake-ups on this VM are bimodal in
  // different proportions, so its median need not be twice the pooled one-way median.
  const auto [rtt_worst, rtt_worst_at] = worstOverRaw(&SizeResult::rtt_p50_us);
  t.push_back(
      {"iceoryx_over_raw_rtt_p50_worst",
       "round-trip p50, ours / raw iceoryx, worst at " + std::to_string(rtt_worst_at) + " B",
       rtt_worst, 1.5, true, rtt_worst_at});
  t.push_back({"uds_over_iceoryx_rtt_p50_1MiB", "round-trip p50 at 1 MiB, Unix socket / ours",
               find("uds", kSizes[2]).r.rtt_p50_us / find("iceoryx", kSizes[2]).r.rtt_p50_us, 25,
               false});
  t.push_back({"uds_over_iceoryx_rtt_p50_4MiB", "round-trip p50 at 4 MiB, Unix socket / ours",
               find("uds", kSizes[3]).r.rtt_p50_us / find("iceoryx", kSizes[3]).r.rtt_p50_us, 100,
               false});
  t.push_back({"iceoryx_msgs_per_s_64B", "streaming msgs/s at 64 B, ours",
               find("iceoryx", kStreamBytes).msgs_per_s.value_or(0), 300000, false});
  return t;
}

/// One row per size from the samples of every round of `transport`, pooled.
void addRows(std::vector<Row>& rows, const std::string& transport,
             const std::vector<const TransportResult*>& rounds, bool has_copies) {
  std::int64_t streamed = 0;
  double stream_s = 0;
  for (const auto* r : rounds) {
    streamed += r->streamed;
    stream_s += r->stream_s;
  }
  for (std::size_t k = 0; k < kSizes.size(); ++k) {
    std::vector<double> one_way, ping, pong, round_trip;
    SizeResult size;
    for (const auto* r : rounds) {
      const RoundSamples& s = r->sizes[k];
      one_way.insert(one_way.end(), s.one_way.begin(), s.one_way.begin() + 2 * s.count);
      for (int i = 0; i < s.count; ++i) {
        ping.push_back(s.one_way[2 * static_cast<std::size_t>(i)]);
        pong.push_back(s.one_way[2 * static_cast<std::size_t>(i) + 1]);
      }
      round_trip.insert(round_trip.end(), s.round_trip.begin(), s.round_trip.begin() + s.count);
      size.copies += s.copies;
    }
    size.ping_p50_us = percentile(ping, 0.5);
    size.pong_p50_us = percentile(pong, 0.5);
    size.p50_us = 0.5 * (size.ping_p50_us + size.pong_p50_us);
    size.p99_us = percentile(one_way, 0.99);
    size.rtt_p50_us = percentile(round_trip, 0.5);
    size.rtt_p99_us = percentile(round_trip, 0.99);
    Row row{transport, kSizes[k], size, std::nullopt, has_copies};
    if (kSizes[k] == kStreamBytes && stream_s > 0) {
      row.msgs_per_s = static_cast<double>(streamed) / stream_s;
    }
    rows.push_back(row);
  }
}

void print(const std::vector<Row>& rows, const std::vector<Target>& targets, const Options& o) {
  if (o.json) {
    nlohmann::json j;
    j["machine"] = machineDescription();
    j["gap_us"] = o.gap_us;
    j["samples"] = o.samples;
    j["rounds"] = o.rounds;
    j["fill"] = fillName(o.fill);
    for (const auto& r : rows) {
      j["results"].push_back(
          {{"transport", r.transport},
           {"payload_bytes", r.payload},
           {"subscribers", 1},
           {"p50_us", r.r.p50_us},
           {"ping_p50_us", r.r.ping_p50_us},
           {"pong_p50_us", r.r.pong_p50_us},
           {"p99_us", r.r.p99_us},
           {"round_trip_p50_us", r.r.rtt_p50_us},
           {"round_trip_p99_us", r.r.rtt_p99_us},
           {"msgs_per_s", r.msgs_per_s ? nlohmann::json(*r.msgs_per_s) : nlohmann::json(nullptr)},
           {"payload_copies",
            r.has_copies ? nlohmann::json(r.r.copies) : nlohmann::json(nullptr)}});
    }
    j["targets"] = nlohmann::json::object();
    for (const auto& t : targets) {
      j["targets"][t.name] = {
          {"value", t.value}, {t.at_most ? "max" : "min", t.limit}, {"met", t.met()}};
      if (t.payload != 0) j["targets"][t.name]["payload_bytes"] = t.payload;
    }
    std::cout << j.dump(2) << "\n";
    return;
  }
  std::cout << "machine: " << machineDescription() << "\n"
            << "one-way latency: stamp before publish -> take in the other process; p50 is the "
               "mean of the ping and pong medians, p99 over both directions; "
            << o.samples << " ping-pongs per size in " << o.rounds << " rounds taking turns, gap "
            << o.gap_us << " us, payloads written " << fillName(o.fill)
            << " (--fill); round trip: ping stamp -> pong take\n\n";
  std::cout << std::left << std::setw(13) << "transport" << std::right << std::setw(10)
            << "payload B" << std::setw(10) << "p50 us" << std::setw(10) << "ping p50"
            << std::setw(10) << "pong p50" << std::setw(10) << "p99 us" << std::setw(12)
            << "rtt p50 us" << std::setw(12) << "rtt p99 us" << std::setw(12) << "msgs/s"
            << std::setw(8) << "copies"
            << "\n"
            << std::fixed;
  for (const auto& r : rows) {
    std::cout << std::left << std::setw(13) << r.transport << std::right << std::setw(10)
              << r.payload << std::setprecision(2) << std::setw(10) << r.r.p50_us << std::setw(10)
              << r.r.ping_p50_us << std::setw(10) << r.r.pong_p50_us << std::setw(10) << r.r.p99_us
              << std::setw(12) << r.r.rtt_p50_us << std::setw(12) << r.r.rtt_p99_us
              << std::setprecision(0) << std::setw(12)
              << (r.msgs_per_s ? std::to_string(static_cast<long>(*r.msgs_per_s)) : "-")
              << std::setw(8) << (r.has_copies ? std::to_string(r.r.copies) : "-") << "\n";
  }
  std::cout << "\n";
  for (const auto& t : targets) {
    std::cout << std::left << std::setw(56) << t.description << std::right
              << std::setprecision(t.value >= 1000 ? 0 : 2) << std::setw(12) << t.value << "   "
              << (t.at_most ? "<= " : ">= ") << std::setprecision(t.limit >= 1000 ? 0 : 1)
              << t.limit << (t.met() ? "   met" : "   NOT met") << "\n";
  }
}

/// A connected Unix-domain socket pair, closed when this goes.
class SocketPair {
 public:
  SocketPair() {
    if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, fds) != 0) {
      throw std::runtime_error(std::string("bench ipc: socketpair: ") + std::strerror(errno));
    }
  }
  ~SocketPair() {
    ::close(fds[0]);
    ::close(fds[1]);
  }
  SocketPair(const SocketPair&) = delete;
  SocketPair& operator=(const SocketPair&) = delete;
  int fds[2] = {-1, -1};
};

void runBench(const Options& o) {
  if (o.samples < 1) throw ConfigError("bench ipc: --samples must be at least 1");
  if (o.rounds < 1) throw ConfigError("bench ipc: --rounds must be at least 1");
  if (o.gap_us < 0) throw ConfigError("bench ipc: --gap-us must not be negative");
  if (o.stream_seconds <= 0) throw ConfigError("bench ipc: --stream-seconds must be positive");
  // What one round of one transport does.
  Options round = o;
  round.samples = (o.samples + o.rounds - 1) / o.rounds;
  round.stream_seconds = o.stream_seconds / o.rounds;
  if (round.samples > kMaxRoundSamples) {
    throw ConfigError("bench ipc: at most " + std::to_string(kMaxRoundSamples) +
                      " samples per round; raise --rounds");
  }
  InterruptGuard interrupts;
  std::vector<Row> rows;
  {
    const auto pools = benchPools();
    std::size_t max_chunk = 0;
    for (const auto& p : pools) max_chunk = std::max(max_chunk, p.chunk_bytes);
    // Every child is forked here, before RouDi's threads exist (see PairRun).
    std::vector<std::unique_ptr<SocketPair>> sockets;
    std::array<std::vector<std::unique_ptr<PairRun>>, 3> pairs;  // ours, raw, uds
    for (int r = 0; r < o.rounds; ++r) {
      pairs[0].push_back(std::make_unique<PairRun>(
          "iceoryx", [&, r](TransportResult& out) { shmLeader(max_chunk, round, out, r); },
          [&, r] { return shmFollower(max_chunk, o.fill, r); },
          std::vector<std::string>{roundName(kShmLeaderName, r), roundName(kShmFollowerName, r)}));
      pairs[1].push_back(std::make_unique<PairRun>(
          "iceoryx_raw", [&, r](TransportResult& out) { rawLeader(round, out, r); },
          [&o, r] { return rawFollower(o.fill, r); },
          std::vector<std::string>{roundName(kRawLeaderName, r), roundName(kRawFollowerName, r)}));
      const int* fds = sockets.emplace_back(std::make_unique<SocketPair>())->fds;
      // Each child closes the other end, so a dead peer shows as a closed socket.
      pairs[2].push_back(std::make_unique<PairRun>(
          "uds",
          [&round, fds](TransportResult& out) {
            ::close(fds[1]);
            UdsLeader link(fds[0], round.fill);
            lead(link, round, out);
          },
          [&o, fds] {
            ::close(fds[0]);
            return udsFollower(fds[1], o.fill);
          }));
    }
    // RouDi prints its start-up to stdout, which belongs to the report (one JSON object).
    StdoutToStderr quiet;
    RouDiHost roudi(RouDiHostOptions{pools});
    if (roudi.maxChunkBytes() != max_chunk) throw std::logic_error("bench ipc: pool sizes");
    std::array<std::vector<const TransportResult*>, 3> results;
    for (int r = 0; r < o.rounds; ++r) {
      for (std::size_t t = 0; t < pairs.size(); ++t) {
        results[t].push_back(&pairs[t][static_cast<std::size_t>(r)]->run(round));
      }
    }
    addRows(rows, "iceoryx", results[0], true);
    addRows(rows, "iceoryx_raw", results[1], false);
    addRows(rows, "uds", results[2], false);
  }
  // In-process: no other process involved; its rounds run back to back.
  std::vector<std::unique_ptr<TransportResult>> inproc;
  for (int r = 0; r < o.rounds; ++r) {
    inprocRun(round, *inproc.emplace_back(std::make_unique<TransportResult>()));
    InterruptGuard::check();
  }
  std::vector<const TransportResult*> inproc_rounds;
  for (const auto& r : inproc) inproc_rounds.push_back(r.get());
  addRows(rows, "inproc", inproc_rounds, false);
  // Table order: by transport then size, as measured.
  print(rows, evaluate(rows), o);
}

}  // namespace

void addBenchIpcCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "ipc",
      "latency and throughput between two processes: our iceoryx transport vs raw "
      "iceoryx, a Unix socket and in-process");
  auto o = std::make_shared<Options>();
  cmd->add_option("--samples", o->samples, "ping-pongs per transport and payload size");
  cmd->add_option("--rounds", o->rounds,
                  "rounds in which the transports take turns (samples are split over them)");
  cmd->add_option("--gap-us", o->gap_us, "idle gap between ping-pongs [us]");
  cmd->add_option("--stream-seconds", o->stream_seconds, "duration of each 64 B streaming run [s]");
  auto fill = std::make_shared<std::string>(fillName(o->fill));
  cmd->add_option("--fill", *fill,
                  "what building a message writes: first-use (a buffer in full when first used, "
                  "then only its header, as iceperf does) or every (each payload in full)")
      ->check(CLI::IsMember({fillName(Fill::kFirstUse), fillName(Fill::kEvery)}));
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, fill, &result] {
    o->fill = *fill == fillName(Fill::kEvery) ? Fill::kEvery : Fill::kFirstUse;
    runBench(*o);
    result = 0;
  });
}

}  // namespace tessera::app
