// SICK LMS2xx: the telegram codec (CRC against the telegram listing's examples, framing,
// resynchronisation after garbage and bad CRCs, scan decoding of truncated and malformed
// telegrams), and SickLmsClient against the emulated SickLmsDevice in memory: the baud search,
// the switch to the session rate, variants, units written through installation mode, streaming,
// and faults. Nothing corrupt is ever returned as a scan.
#include <tessera/drivers/sick_lms.hpp>
#include <tessera/drivers/sick_lms_client.hpp>
#include <tessera/drivers/sick_lms_device.hpp>

#include "byte_strings.hpp"
#include "serial_bench.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace sick_lms_test {

using namespace tessera::drivers;
constexpr std::int64_t kMs = 1'000'000;

using tessera::test::bytes;

TEST_CASE("sick telegrams carry the listing's CRC", "[drivers][sick]") {
  // Stream every scan, stop, 38400 and 500000 baud: the telegrams every LMS driver sends.
  CHECK(sick::frame(0x00, sick::modeCommand(0x24)) == bytes({2, 0, 2, 0, 0x20, 0x24, 0x34, 0x08}));
  CHECK(sick::frame(0x00, sick::modeCommand(0x25)) == bytes({2, 0, 2, 0, 0x20, 0x25, 0x35, 0x08}));
  CHECK(sick::frame(0x00, sick::modeCommand(0x40)) == bytes({2, 0, 2, 0, 0x20, 0x40, 0x50, 0x08}));
  CHECK(sick::frame(0x00, sick::modeCommand(0x48)) == bytes({2, 0, 2, 0, 0x20, 0x48, 0x58, 0x08}));
  CHECK(sick::baudMode(500000) == 0x48);
  CHECK_FALSE(sick::baudMode(115200));
}

TEST_CASE("sick parser finds telegrams in garbage and skips bad CRCs", "[drivers][sick]") {
  sick::Scan scan;
  scan.millimetres = true;
  scan.values = {100, 200, 8191};
  const std::string good = sick::frame(0x80, sick::encodeScan(scan));
  std::string bad = good;
  bad[7] ^= 0x01;  // a value bit: the CRC fails
  std::string stream("\xff\x02\x02zz", 5);
  stream.append(bad);
  stream.push_back('\x06');
  stream.append(good);
  stream.push_back('\x15');
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    sick::TelegramParser parser;
    std::vector<sick::TelegramParser::Item> items;
    for (std::size_t at = 0; at < stream.size();) {
      const std::size_t n = std::min<std::size_t>(1 + rng() % 9, stream.size() - at);
      for (auto& i : parser.feed(std::string_view(stream).substr(at, n))) items.push_back(i);
      at += n;
    }
    using Kind = sick::TelegramParser::Item::Kind;
    std::vector<Kind> kinds;
    for (const auto& i : items) kinds.push_back(i.kind);
    CHECK(kinds == std::vector<Kind>{Kind::kAck, Kind::kTelegram, Kind::kNak});
    CHECK(parser.badCrcs() >= 1);
    std::string error;
    const auto t = std::find_if(items.begin(), items.end(),
                                [](const auto& i) { return i.kind == Kind::kTelegram; });
    REQUIRE(t != items.end());
    const auto decoded = sick::decodeScan(t->telegram, error);
    REQUIRE(decoded);
    CHECK(decoded->values == std::vector<std::uint16_t>{100, 200, 8191});
    CHECK(decoded->millimetres);
  }
}

TEST_CASE("sick scan decoding names truncated, malformed and empty telegrams", "[drivers][sick]") {
  std::string error;
  sick::Telegram t;
  t.command = 0xB0;
  CHECK_FALSE(sick::decodeScan(t, error));
  CHECK_THAT(error, Catch::Contains("too short"));
  sick::Scan s;
  s.values = {1, 2, 3};
  const std::string whole = sick::encodeScan(s);
  t.data.assign(whole, 1, whole.size() - 3);  // a value and the status lost
  CHECK_FALSE(sick::decodeScan(t, error));
  CHECK_THAT(error, Catch::Contains("says 3 values"));
  t.data = sick::encodeScan(s).substr(1);
  t.data[1] = static_cast<char>(0x80);  // units 2: unknown
  CHECK_FALSE(sick::decodeScan(t, error));
  CHECK_THAT(error, Catch::Contains("units"));
  t.command = 0xA0;
  CHECK_FALSE(sick::decodeScan(t, error));
}

/// A room in mm for any variant: beam k of n at angle -angle/2 + k res.
std::vector<std::uint32_t> room(int angle, int res, int sweep) {
  const int n = angle * 100 / res + 1;
  std::vector<std::uint32_t> mm(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k)
    mm[static_cast<std::size_t>(k)] = static_cast<std::uint32_t>(500 + (k * 23 + sweep) % 7000);
  mm[0] = 0;  // no echo
  return mm;
}

/// Client and device wired in memory on a simulated clock, with the baud rates of both ends:
/// at different rates each hears only noise. A reconnect opens the link again at once.
struct Bench : tessera::test::SerialBench<Bench> {
  Bench(SickLmsClientOptions o, int session_baud)
      : device([this](int a, int r) { return room(a, r, sweeps++); }), client(o, session_baud) {}
  SickLmsClient& session() { return client; }
  int openBaud() { return client.openBaud(0); }
  void collect(SessionOutput& out) {
    for (auto& s : out.scans) scans.push_back(std::move(s));
  }
  void lost() { client.disconnected(); }
  int sweeps = 0;
  SickLmsDevice device;
  SickLmsClient client;
  std::vector<LaserReading> scans;
};

TEST_CASE("sick client switches a fresh LMS to 38400 baud, mm and streams its scans",
          "[drivers][sick]") {
  SickLmsClientOptions o;  // 180 deg, 1 deg, mm
  Bench b(o, 38400);
  b.connect();
  // First attempt at the session rate: the LMS is at 9600 since power-up.
  b.run(3000 * kMs);
  REQUIRE(b.client.streaming());
  CHECK(b.reconnects == 1);
  CHECK_THAT(b.reason, Catch::Contains("38400 baud") && Catch::Contains("next baud rate"));
  CHECK(b.device.baud() == 38400);
  CHECK(b.device.millimetres());  // written through installation mode
  REQUIRE(b.scans.size() >= 5);
  const auto& s = b.scans.back();
  REQUIRE(s.ranges.size() == 181);
  CHECK(s.angle_min == Approx(-std::numbers::pi / 2));
  CHECK(s.angle_increment == Approx(std::numbers::pi / 180));
  CHECK(std::isinf(s.ranges[0]));
  CHECK(s.range_max == Approx(8.182f));
  // Every scan is a room sweep, exactly: ranges in mm / 1000.
  for (const auto& scan : b.scans) {
    bool matched = false;
    for (int sweep = 0; sweep <= b.sweeps && !matched; ++sweep) {
      const auto mm = room(180, 100, sweep);
      bool same = true;
      for (std::size_t k = 1; same && k < mm.size(); ++k)
        same = scan.ranges[k] == static_cast<float>(mm[k] * 1e-3);
      matched = same;
    }
    CHECK(matched);
  }
  // 38400 baud carries ~10 of the LMS's 75 sweeps a second; the others are skipped.
  CHECK(b.device.scansSkipped() > b.device.scansSent());
}

TEST_CASE("sick client at 500 kBd streams all 75 scans a second in cm", "[drivers][sick]") {
  SickLmsClientOptions o;
  o.units = "cm";
  o.angle_deg = 100;
  o.resolution_deg = 0.5;
  Bench b(o, 500000);
  b.connect();
  b.run(4000 * kMs);
  REQUIRE(b.client.streaming());
  const std::size_t before = b.scans.size();
  b.run(1000 * kMs);
  // 0.5 deg is two interlaced sweeps: 37.5 scans a second.
  CHECK(b.scans.size() - before >= 36);
  CHECK(b.scans.size() - before <= 39);
  CHECK(b.scans.back().ranges.size() == 201);
  CHECK(b.scans.back().angle_min == Approx(-50 * std::numbers::pi / 180));
  CHECK(b.scans.back().range_max == Approx(81.82f));
  CHECK(b.device.scansSkipped() <= 1);  // at most the one due while the start reply went out
}

TEST_CASE("sick client drops corrupt scans and reconnects to a silent LMS", "[drivers][sick]") {
  SickLmsClientOptions o;
  Bench b(o, 500000);
  b.connect();
  b.run(4000 * kMs);
  REQUIRE(b.client.streaming());
  b.device.faults().corrupt_probability = 0.3;
  b.device.faults().garbage_probability = 0.3;
  b.run(2000 * kMs);
  CHECK(b.client.counters().garbage_bytes > 0);
  for (const auto& scan : b.scans) CHECK(scan.ranges.size() == 181);
  b.device.faults() = {};
  b.device.faults().silent = true;
  const int before = b.reconnects;
  b.run(1500 * kMs);
  CHECK(b.reconnects > before);
  CHECK_THAT(b.reason, Catch::Contains("no scan for") || Catch::Contains("no reply"));
}

TEST_CASE("sick client refuses options the LMS does not have", "[drivers][sick]") {
  SickLmsClientOptions o;
  CHECK_THROWS_WITH(SickLmsClient(o, 115200), Catch::Contains("115200"));
  o.angle_deg = 90;
  CHECK_THROWS_WITH(SickLmsClient(o, 38400), Catch::Contains("angle_deg"));
  o = {};
  o.resolution_deg = 0.25;  // only with 100 deg
  CHECK_THROWS_WITH(SickLmsClient(o, 38400), Catch::Contains("0.25"));
  o = {};
  o.units = "m";
  CHECK_THROWS_WITH(SickLmsClient(o, 38400), Catch::Contains("units"));
}

}  // namespace sick_lms_test
