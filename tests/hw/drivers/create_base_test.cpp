// iRobot Create 2 (Open Interface): the codec (Drive Direct bytes, stream frames and their
// checksum, resynchronisation after garbage and damage, encoder wrap), and CreateBase against
// the emulated CreateDevice in memory: driving, the watchdog, bumper, cliff and wheel-drop stops
// with their reasons, and a robot that stops streaming.
#include <tessera/drivers/create_base.hpp>
#include <tessera/drivers/create_device.hpp>
#include <tessera/drivers/create_oi.hpp>

#include "byte_strings.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace create_base_test {

using namespace tessera::drivers;
constexpr std::int64_t kMs = 1'000'000;

using tessera::test::bytes;

TEST_CASE("oi commands are the specification's bytes", "[drivers][create]") {
  CHECK(oi::driveDirect(200, 200) == bytes({145, 0x00, 0xC8, 0x00, 0xC8}));
  CHECK(oi::driveDirect(-200, 500) == bytes({145, 0xFF, 0x38, 0x01, 0xF4}));
  CHECK(oi::driveDirect(900, std::nan("")) == bytes({145, 0x01, 0xF4, 0x00, 0x00}));  // clamped
  CHECK(oi::streamCommand({7, 43}) == bytes({148, 2, 7, 43}));
}

TEST_CASE("oi stream frames sum to zero and survive garbage and damage", "[drivers][create]") {
  oi::SensorFrame f;
  f.bump_left = true;
  f.cliff_front_right = true;
  f.voltage_mv = 15000;
  f.current_ma = -300;
  f.left_counts = 65530;
  f.right_counts = 12;
  const std::string frame = oi::encodeFrame(f);
  unsigned sum = 0;
  for (const char c : frame) sum += static_cast<std::uint8_t>(c);
  CHECK((sum & 0xFF) == 0);
  std::string damaged = frame;
  damaged[5] ^= 0x10;
  std::string stream("\x13\x13zz\x01", 5);
  stream.append(damaged);
  stream.append(frame);
  stream.append(frame.substr(0, 7));  // cut: held until the rest comes
  std::mt19937 rng(2);
  for (int trial = 0; trial < 10; ++trial) {
    oi::StreamParser p;
    std::vector<oi::SensorFrame> got;
    for (std::size_t at = 0; at < stream.size();) {
      const std::size_t n = std::min<std::size_t>(1 + rng() % 11, stream.size() - at);
      for (auto& x : p.feed(std::string_view(stream).substr(at, n))) got.push_back(x);
      at += n;
    }
    REQUIRE(got.size() == 1);
    CHECK(got[0].bump_left);
    CHECK_FALSE(got[0].bump_right);
    CHECK(got[0].cliff_front_right);
    CHECK(got[0].voltage_mv == 15000);
    CHECK(got[0].current_ma == -300);
    CHECK(got[0].left_counts == 65530);
    CHECK(p.badFrames() >= 1);
  }
  oi::EncoderUnwrap u;
  CHECK(u(65530) == 0);
  CHECK(u(4) == 10);     // forward across the wrap
  CHECK(u(65534) == 4);  // and 6 back across it
}

struct Bench {
  explicit Bench(CreateBaseOptions o = {}) : base(o) {}
  void connect() { apply(base.connected(now)); }
  void run(std::int64_t ns, double vx = 0, double omega = 0, bool commanding = false) {
    const std::int64_t end = now + ns;
    while (now < end) {
      now += kMs;
      if (commanding && now % (50 * kMs) == 0) apply(base.command(vx, omega, now));
      const std::string b = device.poll(now);
      if (!b.empty()) apply(base.received(b, now));
      apply(base.tick(now));
    }
  }
  void apply(BaseOutput out) {
    if (!out.send.empty()) device.receive(out.send, now);
    for (auto& t : out.ticks) ticks.push_back(t);
    for (auto& s : out.status) status.push_back(s);
    for (auto& e : out.events) events.push_back(e);
    if (out.reconnect) reason = out.reconnect_reason;
  }
  CreateDevice device;
  CreateBase base;
  std::int64_t now = 1000 * kMs;
  std::vector<WheelTickReading> ticks;
  std::vector<BaseStatus> status;
  std::vector<std::string> events;
  std::string reason;
};

TEST_CASE("create base drives the robot and reads its encoders", "[drivers][create]") {
  Bench b;
  b.connect();
  b.run(100 * kMs);
  REQUIRE(b.base.streaming());
  CHECK(b.device.mode() == CreateDevice::Mode::kSafe);
  const auto start = b.ticks.back();
  b.run(2000 * kMs, 0.2, 0, true);
  const auto end = b.ticks.back();
  const double counts_per_m = 508.8 / (std::numbers::pi * 0.072);
  CHECK((end.left - start.left) / counts_per_m == Approx(0.4).margin(0.015));
  CHECK((end.right - start.right) / counts_per_m == Approx(0.4).margin(0.015));
  // Turning on the spot: the wheels run opposite at omega * base / 2.
  b.run(200 * kMs, 0, 1.0, true);
  CHECK(b.device.rightSpeed() == Approx(117.5).margin(1));
  CHECK(b.device.leftSpeed() == Approx(-117.5).margin(1));
  CHECK(b.base.counters().frames > 100);
}

TEST_CASE("create base stops the wheels when commands stop coming", "[drivers][create]") {
  Bench b;
  b.connect();
  b.run(500 * kMs, 0.3, 0, true);
  REQUIRE(b.device.rightSpeed() == Approx(300));
  b.run(400 * kMs);  // within the 0.5 s watchdog
  CHECK(b.device.rightSpeed() == Approx(300));
  b.run(200 * kMs);
  CHECK(b.device.rightSpeed() == 0);
  CHECK(b.base.counters().watchdog_stops == 1);
  REQUIRE_FALSE(b.status.empty());
  CHECK_THAT(b.status.back().stop_reason, Catch::Contains("watchdog"));
}

TEST_CASE("create base stops at a bumper and allows only reversing until it is released",
          "[drivers][create]") {
  Bench b;
  b.connect();
  b.run(300 * kMs, 0.2, 0, true);
  b.device.world().bump_left = true;
  b.run(100 * kMs, 0.2, 0, true);
  CHECK(b.device.rightSpeed() == 0);
  CHECK(b.base.counters().safety_stops == 1);
  CHECK_THAT(b.status.back().stop_reason, Catch::Contains("bumper left"));
  CHECK(b.status.back().sensors.bump_left);
  b.run(200 * kMs, 0.2, 0, true);  // forward: refused
  CHECK(b.device.rightSpeed() == 0);
  CHECK(b.base.counters().refused_commands > 0);
  b.run(200 * kMs, -0.1, 0, true);  // reversing away: allowed
  CHECK(b.device.rightSpeed() == Approx(-100));
  b.device.world().bump_left = false;
  b.run(200 * kMs, 0.2, 0, true);
  CHECK(b.device.rightSpeed() == Approx(200));
  CHECK(b.status.back().stop_reason.empty());
}

TEST_CASE("create base stops at a cliff and a wheel drop", "[drivers][create]") {
  Bench b;
  b.connect();
  b.run(300 * kMs, 0.2, 0, true);
  b.device.world().cliff_front_left = true;
  b.run(100 * kMs, 0.2, 0, true);
  CHECK(b.device.rightSpeed() == 0);
  CHECK_THAT(b.status.back().stop_reason, Catch::Contains("cliff"));
  b.device.world().cliff_front_left = false;
  b.device.world().wheel_drop_right = true;
  b.run(200 * kMs, -0.1, 0, true);  // not even reversing with a wheel in the air
  CHECK(b.device.rightSpeed() == 0);
  CHECK_THAT(b.events.back(), Catch::Contains("wheel drop") || Catch::Contains("cliff"));
}

TEST_CASE("create base asks for a reconnect when the robot stops streaming", "[drivers][create]") {
  Bench b;
  b.connect();
  b.run(200 * kMs);
  REQUIRE(b.base.streaming());
  b.device.faults().silent = true;
  b.run(600 * kMs);
  CHECK_THAT(b.reason, Catch::Contains("no sensor frame"));
  CHECK_FALSE(b.base.streaming());
}

TEST_CASE("create base refuses impossible options", "[drivers][create]") {
  CreateBaseOptions o;
  o.max_speed_m_s = 0.7;
  CHECK_THROWS_WITH(CreateBase(o), Catch::Contains("max_speed_m_s"));
  o = {};
  o.wheel_base_m = 0;
  CHECK_THROWS(CreateBase(o));
  o = {};
  o.watchdog_s = std::nan("");
  CHECK_THROWS(CreateBase(o));
}

}  // namespace create_base_test
