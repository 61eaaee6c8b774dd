#include "../test_actors.hpp"
#include "launch_fixtures.hpp"
#include "processes.hpp"

#include <tessera/messages/types.hpp>
#include <tessera/runtime/runtime.hpp>
#include <tessera/shm/roudi_host.hpp>
#include <tessera/shm/shm_transport.hpp>

#include <catch2/catch.hpp>
#include <iceoryx_posh/popo/untyped_publisher.hpp>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

using namespace tessera;
using namespace std::chrono_literals;

namespace {

/// Polls until `file` exists (the test's processes signal each other by files) or `deadline`
/// passes; true when it exists.
bool waitForFile(const std::filesystem::path& file,
                 std::chrono::steady_clock::time_point deadline) {
  while (!std::filesystem::exists(file)) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(2ms);
  }
  return true;
}

RouDiHostOptions smallPools() {
  RouDiHostOptions o;
  o.pools = memPoolsFor({{1 << 16, 64}});
  return o;
}

std::size_t maxChunk(const RouDiHostOptions& o) {
  std::size_t m = 0;
  for (const auto& p : o.pools) m = std::max(m, p.chunk_bytes);
  return m;
}

ShmTopic topic(const std::string& name, bool exported, bool imported, MailboxPolicy policy) {
  ShmTopic t;
  t.name = name;
  t.type = messageTypeOf<msg::Blob>();
  t.exported = exported;
  t.imported = imported;
  t.importing_processes = 1;
  t.any_reliable = policy.kind == MailboxPolicy::Kind::kReliable;
  t.import_policy = policy;
  return t;
}

/// Transport options of process `index` of the test deployment (0 sends, 1 receives).
ShmTransportOptions processOptions(const std::string& runtime_name, std::uint32_t index,
                                   std::size_t max_chunk) {
  ShmTransportOptions so;
  so.runtime_name = runtime_name;
  so.process_index = index;
  so.max_chunk_bytes = max_chunk;
  return so;
}

/// Runs `rx` and `tx` as two processes beside a RouDi with `pools`; both must exit with 0.
void checkPair(const RouDiHostOptions& pools, std::function<int()> rx, std::function<int()> tx) {
  test::Children children;
  const pid_t receiver = children.spawn(std::move(rx));
  const pid_t sender = children.spawn(std::move(tx));
  RouDiHost roudi(pools);
  children.open();
  CHECK(children.wait(sender) == 0);
  CHECK(children.wait(receiver) == 0);
}

/// A sending process's runtime: wall clock, stepped by hand (publishes from the test's thread).
RuntimeOptions manualSenderRuntime() {
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.manual = true;
  return ro;
}

/// A wall-clock runtime with one worker thread, quiet.
RuntimeOptions wallReceiverRuntime() {
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 1;
  ro.show_progress = false;
  return ro;
}

/// A receiving process's transport and runtime: `actor` runs as "rx" with its "in" on
/// `topic_name`, configured and started. The caller starts the receiving thread, or receives on
/// its own thread.
struct ReceiverProcess {
  ReceiverProcess(const ShmTransportOptions& options, const std::string& topic_name,
                  MailboxPolicy policy, std::unique_ptr<Actor> actor)
      : transport(options), rt(wallReceiverRuntime()) {
    added = &rt.add("rx", std::move(actor), {{"in", topic_name}});
    transport.attach(rt, {topic(topic_name, false, true, policy)});
    rt.configure();
    rt.start();
  }
  template <typename A>
  A& actor() {
    return static_cast<A&>(*added);
  }
  ShmTransport transport;  // outlives the runtime, as its imports deliver into it
  Runtime rt;
  Actor* added = nullptr;  // owned by rt
};

/// Receiving process: records every Blob on `topic` until `expected` arrived (or 20 s), then
/// checks order. Returns 0 when complete and in order, 2 when messages are missing, 3 when out
/// of order, 4 when the bytes were not read in place.
int receive(const std::string& topic_name, MailboxPolicy policy, int expected,
            std::chrono::microseconds work, std::size_t max_chunk, bool expect_all) {
  ReceiverProcess rx(processOptions("tessera_test_rx", 1, max_chunk), topic_name, policy,
                     std::make_unique<test::Recorder>(policy, work));
  auto& rec = rx.actor<test::Recorder>();
  rx.transport.startReceiving();
  if (!rx.transport.waitForPublishers(10s)) return 5;
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  std::size_t last = 0;
  auto quiet_since = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(5ms);
    const auto n = rx.transport.stats().received;
    if (n != last) {
      last = n;
      quiet_since = std::chrono::steady_clock::now();
    }
    if (static_cast<int>(n) >= expected) break;
    if (!expect_all && n > 0 && std::chrono::steady_clock::now() - quiet_since > 1s) break;
  }
  rx.rt.stop();
  rx.transport.stopReceiving();
  std::printf("rx: %zu messages, %llu iceoryx drops, %llu local drops\n", rec.seqs.size(),
              static_cast<unsigned long long>(rx.transport.stats().drops),
              static_cast<unsigned long long>(rx.rt.report().actors[0].drops));
  for (std::size_t i = 1; i < rec.seqs.size(); ++i) {
    if (rec.seqs[i] <= rec.seqs[i - 1]) return 3;
  }
  if (expect_all && static_cast<int>(rec.seqs.size()) != expected) return 2;
  if (!expect_all && (rec.seqs.empty() || static_cast<int>(rec.seqs.size()) >= expected)) return 2;
  return 0;
}

/// Sending process: publishes `count` Blobs of `payload` bytes as fast as it can. Returns 0,
/// or 6 when a publish took longer than `max_block` (a blocked publisher).
int send(const std::string& topic_name, MailboxPolicy policy, int count, std::size_t payload,
         std::size_t max_chunk, std::chrono::milliseconds max_block) {
  ShmTransport transport(processOptions("tessera_test_tx", 0, max_chunk));
  Runtime rt(manualSenderRuntime());
  auto t = topic(topic_name, true, false, policy);
  transport.attach(rt, {t});
  auto pub = rt.externalPublisher<msg::Blob>(topic_name);
  rt.configure(true);
  if (!transport.waitForPublishers(10s)) return 5;
  auto slowest = std::chrono::steady_clock::duration::zero();
  for (int i = 0; i < count; ++i) {
    auto loan = pub.loan(payload);
    setHeader(loan->initHeader(), i, "test", pub.nextSeq());
    auto bytes = loan->initPayload(static_cast<unsigned>(payload));
    if (payload > 0) bytes[0] = static_cast<std::uint8_t>(i);
    const auto t0 = std::chrono::steady_clock::now();
    pub.publish(std::move(loan));
    slowest = std::max(slowest, std::chrono::steady_clock::now() - t0);
  }
  std::printf("tx: %d sent, %llu copies, slowest publish %.3f ms\n", count,
              static_cast<unsigned long long>(transport.stats().copies),
              std::chrono::duration<double, std::milli>(slowest).count());
  if (transport.stats().copies != 0) return 7;
  std::this_thread::sleep_for(300ms);  // let the receiver take the last chunks
  return slowest > max_block ? 6 : 0;
}

}  // namespace

TEST_CASE("two processes exchange 10000 messages on a reliable topic without loss or reordering",
          "[shm]") {
  const auto pools = smallPools();
  const auto max_chunk = maxChunk(pools);
  checkPair(
      pools,
      [&] {
        return receive("reliable_blobs", MailboxPolicy::reliable(8), 10000, 0us, max_chunk, true);
      },
      [&] {
        return send("reliable_blobs", MailboxPolicy::reliable(8), 10000, 200, max_chunk, 60000ms);
      });
}

TEST_CASE("a slow keep_latest subscriber in another process drops and the publisher never blocks",
          "[shm]") {
  const auto pools = smallPools();
  const auto max_chunk = maxChunk(pools);
  checkPair(
      pools,
      [&] {
        return receive("latest_blobs", MailboxPolicy::keepLatest(2), 2000, 2000us, max_chunk,
                       false);
      },
      [&] {
        return send("latest_blobs", MailboxPolicy::keepLatest(2), 2000, 200, max_chunk, 50ms);
      });
}

TEST_CASE("a message larger than the largest shared-memory chunk is a clear error", "[shm]") {
  const auto pools = smallPools();
  const auto max_chunk = maxChunk(pools);
  test::Children children;
  auto tx = children.spawn([&] {
    ShmTransport transport(processOptions("tessera_test_big", 0, max_chunk));
    Runtime rt(manualSenderRuntime());
    transport.attach(rt, {topic("big", true, false, MailboxPolicy::reliable())});
    auto pub = rt.externalPublisher<msg::Blob>("big");
    rt.configure(true);
    auto clearError = [](const MessageError& e) {
      const std::string what = e.what();
      return what.find("'big'") != std::string::npos &&
             what.find("largest shared-memory chunk") != std::string::npos;
    };
    try {
      auto loan = pub.loan(max_chunk * 2);
      return 1;
    } catch (const MessageError& e) {
      if (!clearError(e)) return 2;
    }
    try {  // a blob that cannot fit beside the message either
      auto loan = pub.loanWithBlob(max_chunk);
      return 3;
    } catch (const MessageError& e) {
      if (!clearError(e)) return 4;
    }
    return 0;
  });
  RouDiHost roudi(pools);
  children.open();
  CHECK(children.wait(tx) == 0);
}

TEST_CASE("the RouDi host removes shared memory left by a crashed run", "[shm]") {
  const std::filesystem::path stale = "/dev/shm/iceoryx_mgmt";
  // Never fake a stale segment under a live RouDi: truncating its memory would crash it.
  REQUIRE_FALSE(rouDiRunning());
  {
    std::FILE* f = std::fopen(stale.c_str(), "w");
    REQUIRE(f != nullptr);
    std::fclose(f);
  }
  std::vector<std::string> removed;
  {
    RouDiHost roudi(smallPools());
    removed = roudi.removedStale();
  }
  CHECK(std::find(removed.begin(), removed.end(), stale.string()) != removed.end());
  CHECK_FALSE(std::filesystem::exists(stale));  // and RouDi cleaned its own on exit
}

TEST_CASE("the RouDi host limits its shared memory to the current user", "[shm]") {
  REQUIRE_FALSE(rouDiRunning());
  RouDiHost roudi(smallPools());
  namespace fs = std::filesystem;
  int segments = 0;
  for (const auto& entry : fs::directory_iterator("/dev/shm")) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("tessera_sync_", 0) == 0) continue;  // launcher control blocks: 0600 already
    INFO(name);
    ++segments;
    const auto perms = fs::status(entry.path()).permissions();
    CHECK((perms & (fs::perms::group_all | fs::perms::others_all)) == fs::perms::none);
    CHECK((perms & fs::perms::owner_read) != fs::perms::none);
  }
  CHECK(segments >= 2);  // management and data segments
}

TEST_CASE("messages a full keep_latest queue discarded still count as received for the clock",
          "[shm]") {
  // A deployment's clock waits until every message counted as sent was counted as received.
  // The receiving thread here starts only after all 20 were sent, so a queue of 1 discards 19
  // of them before they are taken; they must be accounted for all the same.
  const auto pools = smallPools();
  const auto max_chunk = maxChunk(pools);
  const auto sent_flag = std::filesystem::temp_directory_path() / "tessera_test_gaps_sent";
  std::filesystem::remove(sent_flag);
  constexpr int kCount = 20;
  checkPair(
      pools,
      [&] {
        std::atomic<std::uint64_t> received{0};
        ShmTransportOptions so = processOptions("tessera_test_gaps_rx", 1, max_chunk);
        so.received = &received;
        ReceiverProcess rx(so, "gaps", MailboxPolicy::keepLatest(1),
                           std::make_unique<test::Recorder>(MailboxPolicy::keepLatest(1), 0us));
        auto& rec = rx.actor<test::Recorder>();
        if (!rx.transport.waitForPublishers(10s)) return 5;
        const auto deadline = std::chrono::steady_clock::now() + 20s;
        waitForFile(sent_flag, deadline);
        rx.transport.startReceiving();
        while (received.load() < kCount && std::chrono::steady_clock::now() < deadline)
          std::this_thread::sleep_for(5ms);
        std::this_thread::sleep_for(100ms);  // nothing more may be counted
        rx.rt.stop();
        rx.transport.stopReceiving();
        std::printf("rx: %zu handled, %llu accounted\n", rec.seqs.size(),
                    static_cast<unsigned long long>(received.load()));
        if (rec.seqs.empty()) return 2;
        // Every message is either handled here or counted as discarded, exactly.
        if (rx.transport.stats().drops + rx.transport.stats().received != kCount) return 4;
        return received.load() == kCount ? 0 : 3;
      },
      [&] {
        const int code = send("gaps", MailboxPolicy::keepLatest(1), kCount, 64, max_chunk, 1000ms);
        std::ofstream(sent_flag) << "sent\n";
        return code;
      });
  std::filesystem::remove(sent_flag);
}

namespace {
/// Checks every Blob on "in": even sequence numbers carry a blob whose byte k is (seq + k) mod
/// 251, odd ones a plain payload written only at byte 0, so the rest must read as zero even in
/// a chunk that held a blob before. Counts what it saw and how many were wrong.
class BlobChecker : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::Blob>("in", MailboxPolicy::reliable(8), [this](const Message<msg::Blob>& m) {
      const std::uint64_t seq = m->getHeader().getSeq();
      const auto p = m->getPayload();
      bool ok = p.size() == kBlobPayload;
      for (std::size_t k = 0; ok && k < p.size(); ++k) {
        const auto want = seq % 2 == 0 ? static_cast<kj::byte>((seq + k) % 251)
                          : k == 0     ? static_cast<kj::byte>(seq)
                                       : kj::byte{0};
        ok = p[k] == want;
      }
      ++seen;
      if (!ok) ++wrong;
    });
  }
  static constexpr std::size_t kBlobPayload = 100001;
  std::atomic<int> seen{0}, wrong{0};
};
}  // namespace

TEST_CASE("a blob crosses processes in place and the chunk it used is clean for the next message",
          "[shm]") {
  // Few chunks, so each is used many times, alternately for a blob (written without zeroing)
  // and for a plain message (which must still find zeroed memory).
  RouDiHostOptions pools;
  pools.pools = memPoolsFor({{1 << 17, 40}, {1 << 12, 64}});
  const auto max_chunk = maxChunk(pools);
  constexpr int kCount = 200;
  checkPair(
      pools,
      [&] {
        ReceiverProcess rx(processOptions("tessera_test_blob_rx", 1, max_chunk), "blobs",
                           MailboxPolicy::reliable(8), std::make_unique<BlobChecker>());
        auto& checker = rx.actor<BlobChecker>();
        rx.transport.startReceiving();
        if (!rx.transport.waitForPublishers(10s)) return 5;
        const auto deadline = std::chrono::steady_clock::now() + 20s;
        while (checker.seen.load() < kCount && std::chrono::steady_clock::now() < deadline)
          std::this_thread::sleep_for(5ms);
        rx.rt.stop();
        rx.transport.stopReceiving();
        std::printf("rx: %d messages, %d wrong\n", checker.seen.load(), checker.wrong.load());
        if (checker.seen.load() != kCount) return 2;
        return checker.wrong.load() == 0 ? 0 : 3;
      },
      [&] {
        ShmTransport transport(processOptions("tessera_test_blob_tx", 0, max_chunk));
        Runtime rt(manualSenderRuntime());
        transport.attach(rt, {topic("blobs", true, false, MailboxPolicy::reliable(8))});
        auto pub = rt.externalPublisher<msg::Blob>("blobs");
        rt.configure(true);
        if (!transport.waitForPublishers(10s)) return 5;
        constexpr std::size_t n = BlobChecker::kBlobPayload;
        for (int i = 0; i < kCount; ++i) {
          if (i % 2 == 0) {
            auto loan = pub.loanWithBlob(n);
            setHeader(loan->initHeader(), i, "test", static_cast<std::uint64_t>(i));
            for (std::size_t k = 0; k < n; ++k)
              loan.blob()[k] = static_cast<std::byte>((static_cast<std::size_t>(i) + k) % 251);
            loan->adoptPayload(loan.blobData());
            pub.publish(std::move(loan));
          } else {
            auto loan = pub.loan(n);
            setHeader(loan->initHeader(), i, "test", static_cast<std::uint64_t>(i));
            loan->initPayload(static_cast<unsigned>(n))[0] = static_cast<kj::byte>(i);
            pub.publish(std::move(loan));
          }
        }
        const auto s = transport.stats();
        std::printf("tx: %d sent, %llu copies, %llu heap loans\n", kCount,
                    static_cast<unsigned long long>(s.copies),
                    static_cast<unsigned long long>(s.heap_fallbacks));
        std::this_thread::sleep_for(300ms);  // let the receiver take the last chunks
        return s.copies == 0 ? 0 : 7;        // every message went in place
      });
}

namespace {
/// Counts Blobs on "in" and notes whether each handler ran on `expected_thread`.
class ThreadNoter : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::Blob>("in", MailboxPolicy::reliable(8), [this](const Message<msg::Blob>& m) {
      if (m->getHeader().getSeq() != static_cast<std::uint64_t>(seen)) ++out_of_order;
      if (std::this_thread::get_id() != expected_thread) ++elsewhere;
      ++seen;
    });
  }
  std::thread::id expected_thread;
  int seen = 0, out_of_order = 0, elsewhere = 0;
};
}  // namespace

TEST_CASE("a process without a receiving thread gets its messages on the thread that waits",
          "[shm]") {
  const auto pools = smallPools();
  const auto max_chunk = maxChunk(pools);
  constexpr int kCount = 500;
  checkPair(
      pools,
      [&] {
        ReceiverProcess rx(processOptions("tessera_test_here_rx", 1, max_chunk), "here",
                           MailboxPolicy::reliable(8), std::make_unique<ThreadNoter>());
        auto& noter = rx.actor<ThreadNoter>();
        // Handlers run only inside receiveHere() below, so setting this after start is safe.
        noter.expected_thread = std::this_thread::get_id();
        if (!rx.transport.waitForPublishers(10s)) return 5;
        const auto deadline = std::chrono::steady_clock::now() + 20s;
        while (noter.seen < kCount && std::chrono::steady_clock::now() < deadline)
          rx.transport.receiveHere(std::chrono::milliseconds(50));
        // The receiving thread and receiveHere() exclude each other.
        rx.transport.startReceiving();
        bool refused = false;
        try {
          rx.transport.receiveHere(std::chrono::milliseconds(1));
        } catch (const std::logic_error&) {
          refused = true;
        }
        rx.transport.stopReceiving();
        rx.rt.stop();
        std::printf("rx: %d messages, %d out of order, %d on another thread\n", noter.seen,
                    noter.out_of_order, noter.elsewhere);
        if (noter.seen != kCount || noter.out_of_order != 0) return 2;
        if (noter.elsewhere != 0) return 3;
        return refused ? 0 : 4;
      },

      [&] { return send("here", MailboxPolicy::reliable(8), kCount, 64, max_chunk, 60000ms); });
}

TEST_CASE(
    "a transport cut off from the others never blocks and its own subscribers still "
    "get every message",
    "[shm]") {
  // The receiver takes nothing until the sender is done, so its reliable queue (16) fills: a
  // send after that would wait for it for ever. Cut off, the sender's messages stay in its
  // process and go to its own subscriber only.
  const auto pools = smallPools();
  const auto max_chunk = maxChunk(pools);
  // The sender imports its own topic too, so its publisher has a subscriber before the receiver's
  // has connected: it waits for the receiver's word (a file) before sending, or the first
  // messages could go to its own import only (1 run in 6 did, receiving 0 of 10).
  const auto dir = test::freshDir("shm_cut_off");
  const auto done = dir / "sender_done";
  const auto ready = dir / "receiver_ready";
  constexpr int kBefore = 10, kAfter = 100;
  checkPair(
      pools,
      [&] {
        ReceiverProcess rx(processOptions("tessera_test_cut_rx", 1, max_chunk), "cut",
                           MailboxPolicy::reliable(4),
                           std::make_unique<test::Recorder>(MailboxPolicy::reliable(4)));
        if (!rx.transport.waitForPublishers(10s)) return 5;
        std::ofstream(ready) << "ready\n";
        waitForFile(done, std::chrono::steady_clock::now() + 30s);
        for (int i = 0; i < 20; ++i) rx.transport.receiveHere(std::chrono::milliseconds(50));
        rx.rt.stop();
        const auto seen = rx.actor<test::Recorder>().seqs.size();
        std::printf("rx: %zu messages\n", seen);
        return seen == kBefore ? 0 : 2;
      },
      [&] {
        ShmTransport transport(processOptions("tessera_test_cut_tx", 0, max_chunk));
        Runtime rt(manualSenderRuntime());
        auto& local = static_cast<test::Recorder&>(
            rt.add("local", std::make_unique<test::Recorder>(MailboxPolicy::reliable(1000)),
                   {{"in", "cut"}}));
        auto t = topic("cut", true, true, MailboxPolicy::reliable(1000));
        t.importing_processes = 2;
        transport.attach(rt, {t});
        auto pub = rt.externalPublisher<msg::Blob>("cut");
        rt.configure(true);
        rt.start();
        transport.startReceiving();
        if (!transport.waitForPublishers(10s)) return 5;
        if (!waitForFile(ready, std::chrono::steady_clock::now() + 10s)) return 10;
        const auto publish = [&](int i) {
          auto loan = pub.loan(64);
          setHeader(loan->initHeader(), i, "test", pub.nextSeq());
          loan->initPayload(64);
          pub.publish(std::move(loan));
        };
        for (int i = 0; i < kBefore; ++i) publish(i);
        // The messages sent before come back through the import.
        const auto deadline = std::chrono::steady_clock::now() + 10s;
        while (transport.stats().received < kBefore && std::chrono::steady_clock::now() < deadline)
          std::this_thread::sleep_for(5ms);
        transport.cutOff();
        const auto t0 = std::chrono::steady_clock::now();
        for (int i = kBefore; i < kBefore + kAfter; ++i) publish(i);
        const auto took = std::chrono::steady_clock::now() - t0;
        rt.stop();  // nothing is left pending: what was not sent is not waited for
        transport.stopReceiving();
        std::ofstream(done) << "done\n";
        std::printf("tx: %llu sent, %llu unsent, %zu handled here, cut-off sends took %.1f ms\n",
                    static_cast<unsigned long long>(transport.stats().sent),
                    static_cast<unsigned long long>(transport.stats().unsent), local.seqs.size(),
                    std::chrono::duration<double, std::milli>(took).count());
        if (took > 5s) return 6;
        if (transport.stats().sent != kBefore || transport.stats().unsent != kAfter) return 7;
        if (local.seqs.size() != kBefore + kAfter) return 8;
        for (std::size_t i = 1; i < local.seqs.size(); ++i)
          if (local.seqs[i] <= local.seqs[i - 1]) return 9;  // in the order sent
        return 0;
      });
}

TEST_CASE("malformed messages from another process are dropped and later ones still arrive",
          "[shm]") {
  const auto pools = smallPools();
  const auto max_chunk = maxChunk(pools);
  checkPair(
      pools,
      [&] {
        ReceiverProcess rx(processOptions("tessera_test_bad_rx", 1, max_chunk), "mixed",
                           MailboxPolicy::reliable(8),
                           std::make_unique<test::Recorder>(MailboxPolicy::reliable(8)));
        auto& rec = rx.actor<test::Recorder>();
        rx.transport.startReceiving();
        if (!rx.transport.waitForPublishers(10s)) return 5;
        const auto deadline = std::chrono::steady_clock::now() + 10s;
        // Delivered by the transport: the one with a bad root pointer and the good one.
        while (rx.transport.stats().received < 2 && std::chrono::steady_clock::now() < deadline)
          std::this_thread::sleep_for(5ms);
        std::this_thread::sleep_for(100ms);  // nothing else may arrive
        rx.transport.stopReceiving();
        rx.rt.stop();
        const auto report = rx.rt.report();
        std::printf("rx: %zu handled, %llu malformed, stop reason '%s'\n", rec.seqs.size(),
                    static_cast<unsigned long long>(report.actors[0].malformed),
                    report.stop_reason.c_str());
        if (rec.seqs.size() != 1) return 2;
        if (report.actors[0].malformed != 1 || report.interrupted) return 4;
        return rec.seqs[0] == 7 ? 0 : 3;
      },
      [&] {
        ShmTransport transport(processOptions("tessera_test_bad_tx", 0, max_chunk));
        Runtime rt(manualSenderRuntime());
        transport.attach(rt, {topic("mixed", true, false, MailboxPolicy::reliable(8))});
        auto pub = rt.externalPublisher<msg::Blob>("mixed");
        rt.configure(true);
        // A second, raw port on the same topic, as a foreign or broken sender would use.
        iox::popo::PublisherOptions po;
        po.subscriberTooSlowPolicy = iox::popo::ConsumerTooSlowPolicy::WAIT_FOR_CONSUMER;
        iox::popo::UntypedPublisher raw({"tessera", "mixed", "capnp"}, po);
        if (!transport.waitForPublishers(10s)) return 5;
        const auto until = std::chrono::steady_clock::now() + 10s;
        while (!raw.hasSubscribers() && std::chrono::steady_clock::now() < until)
          std::this_thread::sleep_for(2ms);
        auto sendRaw = [&](const std::function<void(std::byte*)>& write) {
          auto r = raw.loan(256, 8);
          if (r.has_error()) return false;
          auto* p = static_cast<std::byte*>(r.value());
          std::memset(p, 0, 256);
          write(p);
          raw.publish(r.value());
          return true;
        };
        auto table = [](std::byte* p, std::uint32_t count_minus_one, std::uint32_t size) {
          detail::recordChunkExtent(p, 0, 256);  // a valid Tessera prefix
          std::memcpy(p + 16, &count_minus_one, 4);
          std::memcpy(p + 20, &size, 4);
        };
        bool ok = sendRaw([](std::byte* p) { std::memset(p, 0x7f, 64); });  // no Tessera prefix
        ok = ok && sendRaw([&](std::byte* p) { table(p, 100000, 1); });     // absurd segment count
        ok = ok && sendRaw([&](std::byte* p) { table(p, 0, 1u << 20); });   // segment past the end
        ok = ok && sendRaw([&](std::byte* p) {  // a root struct pointer 1000 words past the segment
               table(p, 0, 1);
               const std::uint64_t root = (std::uint64_t{1000} << 2) | (std::uint64_t{1} << 32);
               std::memcpy(p + 24, &root, sizeof(root));
             });
        if (!ok) return 6;
        auto loan = pub.loan(64);
        setHeader(loan->initHeader(), 7, "test", 7);
        pub.publish(std::move(loan));
        std::this_thread::sleep_for(300ms);
        return 0;
      });
}
