// ScipClient against the emulated ScipDevice, bytes passed in memory: the SCIP session, scans
// to metres and angles, and every fault: garbage, corrupt checksums, silence, late replies,
// refusals. Nothing corrupt is ever returned as a scan.
#include <tessera/drivers/scip_client.hpp>
#include <tessera/drivers/scip_device.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>
#include <vector>

namespace scip_client_test {

using namespace tessera::drivers;
constexpr std::int64_t kMs = 1'000'000;

/// Scan k of an emulated URG-04LX: every step a distinct range, so a scan identifies itself.
EmulatedScan rampScan(int k) {
  EmulatedScan s;
  const auto p = ScipDevice::urg04lx();
  for (int step = p.first_step; step <= p.last_step; ++step)
    s.ranges_mm.push_back(static_cast<std::uint32_t>(100 + (step * 7 + k * 13) % 5000));
  s.ranges_mm[0] = 0;  // no return
  s.ranges_mm[1] = 7;  // an error code
  s.intensities.assign(s.ranges_mm.size(), static_cast<std::uint32_t>(1000 + k));
  return s;
}

/// The client and the device wired together, on a simulated clock stepped in 1 ms.
struct Bench {
  explicit Bench(ScipClientOptions o = {}, int scans = 1000000)
      : device(ScipDevice::urg04lx(),
               [this, scans]() -> std::optional<EmulatedScan> {
                 if (made >= scans) return std::nullopt;
                 return rampScan(made++);
               }),
        client(o) {}

  void connect() { exchange(client.connected(now)); }
  void run(std::int64_t duration_ns) {
    const std::int64_t end = now + duration_ns;
    while (now < end) {
      now += kMs;
      const std::string bytes = device.poll(now);
      if (!bytes.empty()) exchange(client.received(bytes, now));
      exchange(client.tick(now));
      if (reconnect_pending) {  // as the driver does: a new session on a reopened link
        reconnect_pending = false;
        exchange(client.connected(now));
      }
    }
  }
  void exchange(ScipClient::Output out) {
    if (!out.send.empty()) device.receive(out.send, now);
    for (auto& s : out.scans) scans.push_back(std::move(s));
    for (auto& e : out.events) events.push_back(e);
    if (out.reconnect) {
      ++reconnects;
      reason = out.reconnect_reason;
      reconnect_pending = auto_reconnect;
    }
  }

  int made = 0;
  ScipDevice device;
  ScipClient client;
  std::int64_t now = 1'000'000 * kMs;
  std::vector<LaserReading> scans;
  std::vector<std::string> events;
  int reconnects = 0;
  std::string reason;
  bool auto_reconnect = false, reconnect_pending = false;
};

/// Which source scan `r` is (in `k`); false when it equals none of them exactly.
bool matchesSource(const LaserReading& r, int& k) {
  for (k = 0; k < 5000; ++k) {
    const auto src = rampScan(k);
    if (r.ranges.size() != src.ranges_mm.size()) return false;
    bool same = std::isinf(r.ranges[0]) && std::isnan(r.ranges[1]);
    for (std::size_t i = 2; same && i < src.ranges_mm.size(); ++i)
      same = r.ranges[i] == static_cast<float>(static_cast<double>(src.ranges_mm[i]) * 1e-3);
    if (same) return true;
  }
  return false;
}

TEST_CASE("scip client streams a URG-04LX's scans with its geometry", "[drivers][scip_client]") {
  Bench b;
  b.connect();
  b.run(1050 * kMs);
  REQUIRE(b.client.state() == ScipClient::State::kStreaming);
  CHECK(b.client.scanEcho() == "MD0044072500000");
  REQUIRE(b.scans.size() >= 10);
  CHECK(b.scans.size() <= 11);
  const auto& s = b.scans.front();
  const double step = 2 * std::numbers::pi / 1024;
  CHECK(s.angle_min == Approx((44 - 384) * step));
  CHECK(s.angle_increment == Approx(step));
  CHECK(s.range_min == Approx(0.02f));
  CHECK(s.range_max == Approx(5.6f));
  CHECK(s.scan_time == Approx(0.1f));
  for (std::size_t k = 0; k < b.scans.size(); ++k) {
    int source = -1;
    CHECK(matchesSource(b.scans[k], source));
    CHECK(source == static_cast<int>(k));  // in order, none lost
    if (k > 0)
      CHECK(b.scans[k].stamp_ns - b.scans[k - 1].stamp_ns == Approx(100 * kMs).margin(kMs));
  }
  CHECK(b.client.counters().bad_replies == 0);
  CHECK(b.reconnects == 0);
}

TEST_CASE("scip client clusters steps and streams intensities", "[drivers][scip_client]") {
  ScipClientOptions o;
  o.first_step = 100;
  o.last_step = 199;
  o.cluster = 3;
  o.intensity = true;
  Bench b(o);
  b.connect();
  b.run(350 * kMs);
  CHECK(b.client.scanEcho() == "ME0100019903000");
  REQUIRE(b.scans.size() >= 3);
  const auto& s = b.scans[0];
  CHECK(s.ranges.size() == 34);  // ceil(100 / 3)
  CHECK(s.intensities.size() == 34);
  CHECK(s.intensities[0] == 1000);
  const double step = 2 * std::numbers::pi / 1024;
  CHECK(s.angle_min == Approx((101 - 384) * step));  // the middle of steps 100..102
  CHECK(s.angle_increment == Approx(3 * step));
  const auto src = rampScan(0);
  const auto at = [&](int stepno) { return src.ranges_mm[static_cast<std::size_t>(stepno - 44)]; };
  CHECK(s.ranges[0] == static_cast<float>(std::min({at(100), at(101), at(102)}) * 1e-3));
}

TEST_CASE("scip client drops corrupt replies and counts garbage, never publishing either",
          "[drivers][scip_client]") {
  Bench b;
  b.device.faults().garbage_probability = 0.3;
  b.device.faults().corrupt_probability = 0.3;
  b.auto_reconnect = true;
  b.connect();
  b.run(20'000 * kMs);
  // The handshake may need a few attempts when its replies are hit.
  REQUIRE(b.scans.size() > 50);
  for (const auto& s : b.scans) {
    int k = -1;
    CHECK(matchesSource(s, k));
  }
  const auto c = b.client.counters();
  CHECK(c.bad_replies > 5);
  CHECK(c.garbage_bytes > 100);
  CHECK(b.scans.size() + static_cast<std::size_t>(c.bad_replies) <= 200);
}

TEST_CASE("scip client asks for a reconnect when the device goes silent",
          "[drivers][scip_client]") {
  Bench b;
  b.connect();
  b.run(500 * kMs);
  REQUIRE(b.client.state() == ScipClient::State::kStreaming);
  b.device.faults().silent = true;
  b.run(1500 * kMs);
  CHECK(b.reconnects == 1);
  CHECK_THAT(b.reason, Catch::Contains("no scan for"));
  CHECK(b.client.state() == ScipClient::State::kDisconnected);

  // Silent from the start: the handshake times out, naming the command.
  Bench quiet;
  quiet.device.faults().silent = true;
  quiet.connect();
  quiet.run(1500 * kMs);
  CHECK(quiet.reconnects == 1);
  CHECK_THAT(quiet.reason, Catch::Contains("no reply to 'SCIP2.0'"));
}

TEST_CASE("scip client waits for a slow device within its timeout", "[drivers][scip_client]") {
  Bench b;
  b.device.faults().reply_delay_s = 0.4;
  b.connect();
  b.run(5000 * kMs);
  CHECK(b.reconnects == 0);
  CHECK(b.scans.size() >= 25);
  // Too slow for the timeout: reconnects, never a scan.
  Bench late;
  late.device.faults().reply_delay_s = 1.5;
  late.connect();
  late.run(1200 * kMs);
  CHECK(late.reconnects == 1);
  CHECK(late.scans.empty());
}

TEST_CASE("scip client reports steps the sensor does not have", "[drivers][scip_client]") {
  ScipClientOptions o;
  o.first_step = 0;  // a URG-04LX starts at 44
  Bench b(o);
  b.connect();
  b.run(100 * kMs);
  CHECK(b.reconnects == 1);
  CHECK_THAT(b.reason, Catch::Contains("outside the sensor's 44..725"));
  CHECK(b.scans.empty());
}

TEST_CASE("scip client refuses bad options", "[drivers][scip_client]") {
  ScipClientOptions o;
  o.cluster = 0;
  CHECK_THROWS_WITH(ScipClient(o), Catch::Contains("cluster"));
  o = {};
  o.first_step = 500;
  o.last_step = 100;
  CHECK_THROWS_WITH(ScipClient(o), Catch::Contains("before first_step"));
  o = {};
  o.scan_timeout_s = std::nan("");
  CHECK_THROWS(ScipClient(o));
}

TEST_CASE("scip device refuses malformed commands as the specification says",
          "[drivers][scip_device]") {
  ScipDevice d(ScipDevice::urg04lx(), [] { return std::optional<EmulatedScan>(rampScan(0)); });
  scip::ReplyParser parser;
  const auto ask = [&](const std::string& cmd) {
    d.receive(cmd, 0);
    const auto replies = parser.feed(d.poll(0));
    REQUIRE(replies.size() == 1);
    return replies[0];
  };
  CHECK(ask("XX\n").status == "0E");
  CHECK(ask("MD0000072501000\n").status == "10");
  CHECK(ask("MD0044099901000\n").status == "11");
  CHECK(ask("MD00440725\n").status == "0C");
  const auto pp = ask("PP\n");
  std::string error;
  const auto params = scip::parseParameters(pp, error);
  INFO(error);
  REQUIRE(params);
  CHECK(params->first_step == 44);
  CHECK(params->model == "URG-04LX(Hokuyo Automatic Co.,Ltd.)");
  const auto gd = scip::decodeScan(ask("GD0044072501\n"), 3);
  REQUIRE(gd.scan);
  CHECK(gd.scan->ranges.size() == 682);
}

TEST_CASE("scip parameters reply: missing, non-numeric and inconsistent fields are named",
          "[drivers][scip]") {
  auto p = ScipDevice::urg04lx();
  scip::ReplyParser parser;
  std::string error;
  auto reply = parser.feed(scip::encodeParametersReply(p)).at(0);
  REQUIRE(scip::parseParameters(reply, error));
  reply.payload.erase(reply.payload.begin() + 3);  // ARES
  CHECK_FALSE(scip::parseParameters(reply, error));
  CHECK_THAT(error, Catch::Contains("ARES is missing"));
  p.scan_rpm = 0;
  reply = parser.feed(scip::encodeParametersReply(p)).at(0);
  CHECK_FALSE(scip::parseParameters(reply, error));
  CHECK_THAT(error, Catch::Contains("inconsistent"));
  std::string text = scip::encodeParametersReply(ScipDevice::urg04lx());
  text.replace(text.find("DMAX:5600"), 9, "DMAX:5x00");
  reply = parser.feed(text).at(0);
  CHECK_FALSE(scip::parseParameters(reply, error));  // its checksum fails first
  CHECK_FALSE(error.empty());
}

}  // namespace scip_client_test
