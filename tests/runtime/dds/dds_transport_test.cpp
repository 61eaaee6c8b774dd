#include "../test_actors.hpp"

#include <tessera/dds/dds_transport.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/runtime.hpp>

#include "tessera_frame.h"

#include <dds/dds.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>
#include <catch2/catch.hpp>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <thread>

using namespace tessera;
using namespace std::chrono_literals;

namespace {

/// Options of a test transport: loopback only, a partition of this test process, so parallel
/// test processes never see each other's samples.
DdsOptions loopback(const std::string& partition_suffix = "") {
  DdsOptions o;
  o.domain = 17;
  o.interface = "lo";
  o.peers = {"127.0.0.1"};
  o.partition = "tessera_test_" + std::to_string(::getpid()) + partition_suffix;
  return o;
}

DdsTopic blobTopic(const std::string& name, bool exported, bool imported, bool reliable,
                   std::uint32_t depth = 1) {
  DdsTopic t;
  t.name = name;
  t.type = messageTypeOf<msg::Blob>();
  t.exported = exported;
  t.imported = imported;
  t.reliable = reliable;
  t.depth = depth;
  return t;
}

RuntimeOptions wallRuntime(bool manual) {
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.manual = manual;
  ro.threads = 1;
  ro.show_progress = false;
  return ro;
}

/// One receiving host: a Recorder on `topic`.
struct Receiver {
  Receiver(const DdsOptions& options, const DdsTopic& topic, MailboxPolicy policy,
           std::chrono::microseconds work = {})
      : transport(options, "rx"), rt(wallRuntime(false)) {
    recorder = &static_cast<test::Recorder&>(
        rt.add("rx", std::make_unique<test::Recorder>(policy, work), {{"in", topic.name}}));
    transport.attach(rt, {topic});
    rt.configure();
    rt.start();
    transport.startReceiving();
  }
  ~Receiver() { finish(); }
  /// Stops receiving and stops the runtime (handlers done), so the recorder can be read.
  void finish() {
    transport.stopReceiving();
    rt.stop();
  }
  std::size_t handled() {
    std::size_t n = 0;
    for (const auto& a : rt.report().actors) n += a.messages_in;
    return n;
  }
  DdsTransport transport;
  Runtime rt;
  test::Recorder* recorder = nullptr;
};

/// One sending host: an external publisher on `topic`, stepped by the test.
struct Sender {
  Sender(const DdsOptions& options, const DdsTopic& topic)
      : transport(options, "tx"), rt(wallRuntime(true)) {
    transport.attach(rt, {topic});
    pub = rt.externalPublisher<msg::Blob>(topic.name);
    rt.configure(true);
  }
  void send(int i, std::size_t payload) {
    auto loan = pub.loan(payload);
    setHeader(loan->initHeader(), i, "test", pub.nextSeq());
    auto bytes = loan->initPayload(static_cast<unsigned>(payload));
    for (std::size_t k = 0; k < payload; ++k)
      bytes[k] = static_cast<std::uint8_t>((k / 64 + i) & 0xff);
    pub.publish(std::move(loan));
  }
  DdsTransport transport;
  Runtime rt;
  Publisher<msg::Blob> pub;
};

template <typename Pred>
bool waitFor(Pred pred, std::chrono::milliseconds timeout = 20s) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!pred()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(2ms);
  }
  return true;
}

}  // namespace

TEST_CASE("two hosts exchange 2000 messages on a reliable DDS topic without loss or reordering",
          "[dds]") {
  const auto options = loopback();
  const auto topic = blobTopic("blobs", false, true, true);
  Receiver rx(options, topic, MailboxPolicy::reliable(4), 50us);
  Sender tx(options, blobTopic("blobs", true, false, true));
  REQUIRE(tx.transport.waitForPeers(10s));
  REQUIRE(rx.transport.waitForPeers(10s));
  for (int i = 0; i < 2000; ++i) tx.send(i, 300);
  REQUIRE(waitFor([&] { return rx.handled() >= 2000; }));
  rx.finish();
  const auto& seqs = rx.recorder->seqs;
  REQUIRE(seqs.size() == 2000);
  for (std::size_t i = 0; i < seqs.size(); ++i) CHECK(seqs[i] == i);
  const auto sent = tx.transport.stats().total();
  const auto got = rx.transport.stats().total();
  CHECK(sent.sent == 2000);
  CHECK(got.received == 2000);
  CHECK(got.lost == 0);
  CHECK(got.rejected == 0);
}

// The sending host of the next tests, run as a child process: inside one process Cyclone hands
// samples over directly, never through the acknowledgement, discovery and lease protocols these
// tests are about. TESSERA_DDS_CHILD_MODE says what it does:
//   leave  waits for its reader, writes 7 messages, leaves (without a flush if NO_FLUSH is set)
//   late   writes 20 messages before any reader exists, then waits for one and leaves
//   pause  writes 5, sleeps 2 s (the parent stops it meanwhile), writes 5 more, leaves
//   crash  writes 3 and sleeps until the parent kills it
TEST_CASE("dds child: a sending host", "[.][dds_child]") {
  const char* partition = std::getenv("TESSERA_DDS_CHILD_PARTITION");
  const char* mode_env = std::getenv("TESSERA_DDS_CHILD_MODE");
  REQUIRE(partition != nullptr);
  REQUIRE(mode_env != nullptr);
  const std::string mode = mode_env;
  auto options = loopback();
  options.partition = partition;
  options.reliable_depth = 2;
  options.lease_s = 1;
  Sender tx(options, blobTopic("blobs", true, false, true));
  if (mode == "late") {
    for (int i = 0; i < 20; ++i) tx.send(i, 100);
  }
  REQUIRE(tx.transport.waitForPeers(20s));
  if (mode == "leave") {
    for (int i = 0; i < 7; ++i) tx.send(i, 100);
    if (std::getenv("TESSERA_DDS_CHILD_NO_FLUSH") != nullptr) return;
  } else if (mode == "pause") {
    for (int i = 0; i < 5; ++i) tx.send(i, 100);
    std::this_thread::sleep_for(2s);
    for (int i = 5; i < 10; ++i) tx.send(i, 100);
  } else if (mode == "crash") {
    for (int i = 0; i < 3; ++i) tx.send(i, 100);
    std::this_thread::sleep_for(600s);
  }
  CHECK(tx.transport.flush(60s).empty());
}

namespace {
/// Starts the sending host above in `mode` on `partition`; its pid.
pid_t spawnSender(const std::string& mode, const std::string& partition) {
  ::setenv("TESSERA_DDS_CHILD_PARTITION", partition.c_str(), 1);
  ::setenv("TESSERA_DDS_CHILD_MODE", mode.c_str(), 1);
  const std::string exe = std::filesystem::read_symlink("/proc/self/exe").string();
  const std::string name = "dds child: a sending host";
  char* argv[] = {const_cast<char*>(exe.c_str()), const_cast<char*>(name.c_str()), nullptr};
  pid_t child = 0;
  REQUIRE(::posix_spawn(&child, exe.c_str(), nullptr, nullptr, argv, environ) == 0);
  return child;
}
/// Loopback options with a short lease (a frozen or killed host counts as gone after 1 s).
DdsOptions shortLease(const std::string& suffix, double reconnect_timeout_s = 120) {
  auto options = loopback(suffix);
  options.lease_s = 1;
  options.reconnect_timeout_s = reconnect_timeout_s;
  return options;
}
/// 0, 1, ..., n - 1: the sequence numbers of a sender's first n messages.
std::vector<std::uint64_t> firstSeqs(std::size_t n) {
  std::vector<std::uint64_t> seqs(n);
  for (std::size_t i = 0; i < n; ++i) seqs[i] = i;
  return seqs;
}
bool exitedCleanly(pid_t child) {
  int status = 0;
  return ::waitpid(child, &status, 0) == child && WIFEXITED(status) && WEXITSTATUS(status) == 0;
}
}  // namespace

TEST_CASE(
    "a host leaving right after its last reliable message loses none of it, and the receiving "
    "host sees it gone only once drained",
    "[dds]") {
  auto options = loopback("_leave");
  options.reliable_depth = 2;
  options.lease_s = 1;
  // A slow subscriber: when the sender leaves, its last samples wait for longer than Cyclone
  // lingers for them on its own.
  Receiver rx(options, blobTopic("blobs", false, true, true), MailboxPolicy::reliable(1), 500ms);
  CHECK(exitedCleanly(spawnSender("leave", options.partition)));
  REQUIRE(waitFor([&] { return rx.transport.upstreamLeft() && rx.transport.drained(); }, 60s));
  CHECK(rx.transport.stats().topics.at("blobs").received == 7);
  CHECK(rx.transport.stats().topics.at("blobs").lost == 0);
  REQUIRE(waitFor([&] { return rx.handled() >= 7; }));
}

TEST_CASE("a host that starts after its sender gets the messages sent before it joined", "[dds]") {
  const auto options = shortLease("_late");
  const pid_t child = spawnSender("late", options.partition);
  std::this_thread::sleep_for(1500ms);  // the sender writes with no reader anywhere
  Receiver rx(options, blobTopic("blobs", false, true, true), MailboxPolicy::reliable(32));
  CHECK(exitedCleanly(child));
  REQUIRE(waitFor([&] { return rx.transport.upstreamLeft() && rx.transport.drained(); }, 30s));
  REQUIRE(waitFor([&] { return rx.handled() >= 20; }));
  rx.finish();
  CHECK(rx.recorder->seqs == firstSeqs(20));
  CHECK(rx.transport.stats().topics.at("blobs").lost == 0);
}

TEST_CASE("after a lost link the sender replays what the receiver missed, and nothing twice",
          "[dds]") {
  const auto options = shortLease("_pause", 60);
  Receiver rx(options, blobTopic("blobs", false, true, true), MailboxPolicy::reliable(32));
  const pid_t child = spawnSender("pause", options.partition);
  REQUIRE(waitFor([&] { return rx.handled() >= 5; }));
  // The link goes: the sender stops answering until this host's lease on it ran out.
  ::kill(child, SIGSTOP);
  CHECK(waitFor([&] { return !rx.transport.unconnected().empty(); }, 10s));
  CHECK_FALSE(rx.transport.upstreamLeft());  // gone without ending: it may come back
  ::kill(child, SIGCONT);
  CHECK(exitedCleanly(child));
  REQUIRE(waitFor([&] { return rx.transport.upstreamLeft() && rx.transport.drained(); }, 30s));
  REQUIRE(waitFor([&] { return rx.handled() >= 10; }));
  rx.finish();
  CHECK(rx.recorder->seqs == firstSeqs(10));
  const auto s = rx.transport.stats().topics.at("blobs");
  CHECK(s.lost == 0);
  CHECK(s.received == 10);
  CHECK(s.duplicates > 0);  // the replay after the link came back held samples it had
}

TEST_CASE("a sender that vanishes without ending counts as gone after dds.reconnect_timeout_s",
          "[dds]") {
  const auto options = shortLease("_crash", 2);
  Receiver rx(options, blobTopic("blobs", false, true, true), MailboxPolicy::reliable(32));
  const pid_t child = spawnSender("crash", options.partition);
  REQUIRE(waitFor([&] { return rx.handled() >= 3; }));
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  REQUIRE(waitFor([&] { return !rx.transport.unconnected().empty(); }, 10s));
  const auto gone = std::chrono::steady_clock::now();
  CHECK_FALSE(rx.transport.upstreamLeft());
  REQUIRE(waitFor([&] { return rx.transport.upstreamLeft(); }, 10s));
  CHECK(std::chrono::steady_clock::now() - gone >= 1900ms);
}

TEST_CASE("a compressed DDS topic arrives byte-identical and smaller on the wire", "[dds]") {
  auto options = loopback();
  options.compression["maps"] = 3;
  Receiver rx(options, blobTopic("maps", false, true, true), MailboxPolicy::reliable(8));
  Sender tx(options, blobTopic("maps", true, false, true));
  REQUIRE(tx.transport.waitForPeers(10s));
  std::vector<std::size_t> sizes{100, 70000, 1 << 20};
  for (std::size_t i = 0; i < sizes.size(); ++i) tx.send(static_cast<int>(i), sizes[i]);
  REQUIRE(waitFor([&] { return rx.handled() >= sizes.size(); }));
  const auto s = tx.transport.stats().topics.at("maps");
  CHECK(s.bytes_sent * 10 < s.bytes_raw);  // the payload repeats every 64 bytes
  CHECK(s.compress_s > 0);
  CHECK(rx.transport.stats().topics.at("maps").received == 3);
  CHECK(rx.transport.stats().topics.at("maps").rejected == 0);
}

TEST_CASE("a slow keep_latest subscriber on another host drops and the DDS writer never blocks",
          "[dds]") {
  const auto options = loopback();
  Receiver rx(options, blobTopic("latest", false, true, false, 2), MailboxPolicy::keepLatest(2),
              2000us);
  Sender tx(options, blobTopic("latest", true, false, false, 2));
  REQUIRE(tx.transport.waitForPeers(10s));
  auto slowest = std::chrono::steady_clock::duration::zero();
  for (int i = 0; i < 2000; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    tx.send(i, 200);
    slowest = std::max(slowest, std::chrono::steady_clock::now() - t0);
  }
  std::this_thread::sleep_for(300ms);
  CHECK(slowest < 50ms);
  CHECK(rx.handled() > 0);
  CHECK(rx.handled() < 2000);
  rx.finish();
  const auto& seqs = rx.recorder->seqs;
  for (std::size_t i = 1; i < seqs.size(); ++i) CHECK(seqs[i] > seqs[i - 1]);
}

TEST_CASE("a host in another DDS partition never receives and says which topic waits", "[dds]") {
  Receiver rx(loopback("_a"), blobTopic("blobs", false, true, true), MailboxPolicy::reliable(4));
  Sender tx(loopback("_b"), blobTopic("blobs", true, false, true));
  CHECK_FALSE(tx.transport.waitForPeers(1500ms));
  CHECK(tx.transport.unconnected() == std::vector<std::string>{"'blobs' (no subscriber)"});
  CHECK(rx.transport.unconnected() == std::vector<std::string>{"'blobs' (no publisher)"});
  tx.send(0, 10);
  std::this_thread::sleep_for(200ms);
  CHECK(rx.handled() == 0);
}

TEST_CASE(
    "malformed, truncated, empty, oversized and foreign-type DDS samples are dropped and counted",
    "[dds]") {
  auto options = loopback();
  options.max_message_bytes = 1 << 16;
  Receiver rx(options, blobTopic("blobs", false, true, true), MailboxPolicy::reliable(16));

  // A raw writer on the same DDS topic and partition, sending what a broken or hostile peer may.
  const dds_entity_t participant = dds_create_participant(options.domain, nullptr, nullptr);
  REQUIRE(participant > 0);
  dds_qos_t* qos = dds_create_qos();
  dds_qset_partition1(qos, options.partition.c_str());
  const dds_entity_t publisher = dds_create_publisher(participant, qos, nullptr);
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
  dds_qset_durability(qos, DDS_DURABILITY_TRANSIENT_LOCAL);  // as reliable readers ask
  const dds_entity_t topic =
      dds_create_topic(participant, &tessera_dds_Frame_desc, "tessera/blobs", nullptr, nullptr);
  const dds_entity_t writer = dds_create_writer(publisher, topic, qos, nullptr);
  dds_delete_qos(qos);
  REQUIRE(writer > 0);
  REQUIRE(rx.transport.waitForPeers(10s));

  const auto good = encodeMessage(*makeMessage<msg::Blob>([](auto b) {
                                     setHeader(b.initHeader(), 5, "test", 77);
                                     b.initPayload(40);
                                   }).storage());
  std::uint64_t next_seq = 0;
  auto write = [&](std::uint64_t type_id, std::uint8_t codec, std::vector<std::byte> payload,
                   std::uint32_t raw_bytes) {
    tessera_dds_Frame f{};
    f.type_id = type_id;
    f.origin = 42;
    f.seq = next_seq++;  // a repeated number would be taken for a replay and skipped
    f.codec = codec;
    f.raw_bytes = raw_bytes;
    f.payload._buffer = reinterpret_cast<std::uint8_t*>(payload.data());
    f.payload._length = static_cast<std::uint32_t>(payload.size());
    f.payload._maximum = f.payload._length;
    REQUIRE(dds_write(writer, &f) == DDS_RETCODE_OK);
  };
  const auto blob = messageTypeOf<msg::Blob>().id;
  const auto sz = [](const std::vector<std::byte>& v) {
    return static_cast<std::uint32_t>(v.size());
  };
  write(blob + 1, 0, good, sz(good));  // foreign type
  auto truncated = std::vector<std::byte>(good.begin(), good.begin() + 12);
  write(blob, 0, truncated, sz(truncated));  // truncated
  std::vector<std::byte> garbage(64, std::byte{0xff});
  write(blob, 0, garbage, sz(garbage));                     // malformed
  write(blob, 0, {}, 0);                                    // empty
  write(blob, 0, good, sz(good) + 8);                       // size disagrees
  write(blob, 2, garbage, sz(garbage));                     // a malformed lone segment
  write(blob, 2, good, sz(good) - 8);                       // a lone segment whose size disagrees
  write(blob, 9, good, sz(good));                           // unknown codec
  write(blob, 1, detail::zstdCompress(good, 1), 1u << 30);  // zstd bomb claim
  write(blob, 1, garbage, sz(good));                        // corrupt zstd
  std::vector<std::byte> big((1 << 16) + 1024);             // under Cyclone's own cap, over ours
  write(blob, 0, big, sz(big));                             // over the cap
  write(blob, 0, good, sz(good));                           // and a good one
  REQUIRE(waitFor([&] { return rx.handled() >= 1; }));
  REQUIRE(waitFor([&] { return rx.transport.stats().total().rejected >= 11; }));
  CHECK(rx.transport.stats().total().rejected == 11);
  CHECK(rx.transport.stats().total().received == 1);
  rx.finish();
  CHECK(rx.recorder->seqs == std::vector<std::uint64_t>{77});
  dds_delete(participant);
}

TEST_CASE("DDS options are checked: partition required, domain and levels in range", "[dds]") {
  DdsOptions o;
  CHECK_THROWS_WITH(DdsTransport::validate(o), Catch::Contains("dds.partition: missing"));
  o.partition = "lab";
  o.domain = 231;
  CHECK_THROWS_WITH(DdsTransport::validate(o), Catch::Contains("dds.domain: 231"));
  o.domain = 0;
  o.compression["map"] = 25;
  CHECK_THROWS_WITH(DdsTransport::validate(o), Catch::Contains("dds.compression.map: level 25"));
  o.compression["map"] = 3;
  CHECK_NOTHROW(DdsTransport::validate(o));
  o.lease_s = 0.1;
  CHECK_THROWS_WITH(DdsTransport::validate(o), Catch::Contains("dds.lease_s: 0.1"));
  o.lease_s = std::nan("");
  CHECK_THROWS_WITH(DdsTransport::validate(o), Catch::Contains("dds.lease_s"));
  o.lease_s = 2;
  o.reconnect_timeout_s = -1;
  CHECK_THROWS_WITH(DdsTransport::validate(o), Catch::Contains("dds.reconnect_timeout_s"));
  o.reconnect_timeout_s = 5;
  o.replay_depth = 1u << 21;
  CHECK_THROWS_WITH(DdsTransport::validate(o), Catch::Contains("dds.replay_depth"));
  o.replay_depth = 16;
  CHECK_NOTHROW(DdsTransport::validate(o));
  o.interface = "lo";
  o.peers = {"10.0.0.2"};
  const auto xml = DdsTransport::configXml(o);
  CHECK(xml.find("<NetworkInterface name=\"lo\"/>") != std::string::npos);
  CHECK(xml.find("<Peer address=\"10.0.0.2\"/>") != std::string::npos);
  CHECK(xml.find("<LeaseDuration>2000ms</LeaseDuration>") != std::string::npos);
}

TEST_CASE("a message over dds.max_message_bytes is a clear error on the sending host", "[dds]") {
  auto options = loopback();
  options.max_message_bytes = 4096;
  Sender tx(options, blobTopic("big", true, false, true));
  CHECK_THROWS_WITH(tx.send(0, 8000), Catch::Contains("exceeds dds.max_message_bytes"));
}

TEST_CASE("zstd frames: round trip, and a size claim over the cap is refused before allocating",
          "[dds]") {
  std::vector<std::byte> data(10000);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::byte>(i % 7);
  const auto packed = detail::zstdCompress(data, 3);
  CHECK(packed.size() < data.size() / 10);
  CHECK(detail::zstdDecompress(packed, data.size(), 1 << 20, "t") == data);
  CHECK_THROWS_WITH(detail::zstdDecompress(packed, 1 << 21, 1 << 20, "t"),
                    Catch::Contains("more than the limit"));
  CHECK_THROWS_WITH(detail::zstdDecompress(packed, 9999, 1 << 20, "t"),
                    Catch::Contains("the sample says 9999"));
  std::vector<std::byte> cut(packed.begin(), packed.begin() + static_cast<long>(packed.size() / 2));
  CHECK_THROWS(detail::zstdDecompress(cut, data.size(), 1 << 20, "t"));
}
