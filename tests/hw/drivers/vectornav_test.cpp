// VectorNav VN-100 ASCII protocol: the codec (the manual's checksum, VNYMR and VNIMU lines,
// truncated, malformed, NaN, empty and wrong-checksum lines each named, the body-to-REP-103
// flip, lines split from any chunks), the emulated VectorNavDevice's refusals, and VectorNavImu
// against the emulator in memory: the baud search and switch, streaming at 100 Hz with the right
// signs, VNERR replies, late replies, silence and reconnect, and damage never returned.
#include <tessera/drivers/vectornav.hpp>
#include <tessera/drivers/vectornav_device.hpp>
#include <tessera/drivers/vectornav_imu.hpp>

#include "serial_bench.hpp"

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace vectornav_test {

using namespace tessera::drivers;
constexpr std::int64_t kMs = 1'000'000;

/// `body` framed with its true checksum, without CR LF (a line as the splitter gives it).
std::string line(const std::string& body) {
  std::string l = vn::frame(body);
  return l.substr(0, l.size() - 2);
}

vn::Problem problemOf(const std::string& text) {
  vn::Problem p;
  auto m = vn::parseLine(text, p);
  if (m) {
    const auto s = vn::decodeSample(*m, p);
    if (s) p = {};
  }
  return p;
}

TEST_CASE("vectornav checksum is the XOR of the bytes between '$' and '*'",
          "[drivers][vectornav]") {
  // The manual's example $VNRRG,11*73, by hand: V 56 ^ N 4E = 18, ^ R 52 = 4A, ^ R 52 = 18,
  // ^ G 47 = 5F, ^ ',' 2C = 73, ^ '1' 31 = 42, ^ '1' 31 = 73.
  CHECK(vn::checksum("VNRRG,11") == 0x73);
  CHECK(vn::frame("VNRRG,11") == "$VNRRG,11*73\r\n");
  // 73 ^ '0' 30 = 43, ^ '1' 31 = 72.
  CHECK(vn::readRegister(1) == "$VNRRG,01*72\r\n");
  // V^N 18, ^ W 57 = 4F, ^ R 52 = 1D, ^ G 47 = 5A, ^ ',' = 76, ^ '0' = 46, ^ '6' 36 = 70,
  // ^ ',' = 5C, ^ '1' = 6D, ^ '9' 39 = 54.
  CHECK(vn::writeRegister(6, "19") == "$VNWRG,06,19*54\r\n");
  vn::Problem p;
  CHECK(vn::parseLine("$VNRRG,11*73", p));
  CHECK(vn::parseLine("$VNRRG,11*73", p)->fields == std::vector<std::string>{"11"});
  // "*XX" (no checksum) only where the device accepts it from a host.
  CHECK_FALSE(vn::parseLine("$VNRRG,11*XX", p));
  CHECK(vn::parseLine("$VNRRG,11*XX", p, true));
}

TEST_CASE("vectornav reads VNYMR and VNIMU lines", "[drivers][vectornav]") {
  vn::Problem p;
  const auto ymr = vn::parseLine(
      line("VNYMR,+010.071,-000.278,-001.773,+01.0655,-00.2186,+03.3976,-00.307,+00.030,-09.815,"
           "+00.001,-00.002,-00.500"),
      p);
  REQUIRE(ymr);
  CHECK(ymr->header == "VNYMR");
  const auto s = vn::decodeSample(*ymr, p);
  REQUIRE(s);
  CHECK(s->type == vn::kTypeYmr);
  CHECK(s->yaw_deg == Approx(10.071));
  CHECK(s->roll_deg == Approx(-1.773));
  CHECK(s->mag_gauss[2] == Approx(3.3976));
  CHECK(s->accel[2] == Approx(-9.815));
  CHECK(s->gyro[1] == Approx(-0.002));
  CHECK(s->gyro[2] == Approx(-0.5));
  CHECK(std::isnan(s->temperature_c));

  const auto imu = vn::parseLine(
      line("VNIMU,+00.2012,-00.0001,+00.4500,+0.0100,-0.0200,-9.8066,+0.001000,-0.002000,"
           "-0.500000,+25.3,+101.325"),
      p);
  REQUIRE(imu);
  const auto t = vn::decodeSample(*imu, p);
  REQUIRE(t);
  CHECK(t->type == vn::kTypeImu);
  CHECK(std::isnan(t->yaw_deg));
  CHECK(t->accel[0] == Approx(0.01));
  CHECK(t->gyro[2] == Approx(-0.5));
  CHECK(t->temperature_c == Approx(25.3));
  CHECK(t->pressure_kpa == Approx(101.325));

  // What the emulator writes, it reads back.
  vn::Sample u = *t;
  u.gyro = {0.123456, -1.5, 2.25};
  const auto back = vn::decodeSample(*vn::parseLine(line(vn::encodeSample(u)), p), p);
  REQUIRE(back);
  CHECK(back->gyro == u.gyro);
}

TEST_CASE("vectornav names a truncated line", "[drivers][vectornav]") {
  auto p = problemOf("$VNYMR,+010.071,-000.2");  // cut before the checksum
  CHECK(p.fault == vn::Fault::kTruncated);
  CHECK_THAT(p.what, Catch::Contains("without '*'"));
  p = problemOf("$VNRRG,01*7");
  CHECK(p.fault == vn::Fault::kTruncated);
  CHECK_THAT(p.what, Catch::Contains("cut short"));
  // Whole and checksummed, but 9 of VNYMR's 12 values.
  p =
      problemOf(line("VNYMR,+010.071,-000.278,-001.773,+01.0655,-00.2186,+03.3976,-00.307,"
                     "+00.030,-09.815"));
  CHECK(p.fault == vn::Fault::kTruncated);
  CHECK_THAT(p.what, Catch::Contains("VNYMR with 9 values, not 12"));
}

TEST_CASE("vectornav names a malformed line", "[drivers][vectornav]") {
  auto p = problemOf(
      line("VNIMU,+00.2012,-00.0001,+0x.4500,+0.0100,-0.0200,-9.8066,+0.0010,-0.0020,-0.5000,"
           "+25.3,+101.325"));
  CHECK(p.fault == vn::Fault::kMalformed);
  CHECK_THAT(p.what, Catch::Contains("value 3 (mag z) '+0x.4500' is not a number"));
  p =
      problemOf(line("VNIMU,+00.2012,,+00.4500,+0.0100,-0.0200,-9.8066,+0.0010,-0.0020,-0.5000,"
                     "+25.3,+101.325"));
  CHECK(p.fault == vn::Fault::kMalformed);
  CHECK_THAT(p.what, Catch::Contains("value 2 (mag y) is empty"));
  p = problemOf(line("GPGGA,1,2"));
  CHECK(p.fault == vn::Fault::kMalformed);
  CHECK_THAT(p.what, Catch::Contains("'GPGGA' is not a VN-100 message"));
  p = problemOf("$VNRRG,01*G2");
  CHECK(p.fault == vn::Fault::kMalformed);
  CHECK_THAT(p.what, Catch::Contains("not two hex digits"));
  p = problemOf(line(std::string("VNRRG,0\x07", 8)));  // checksummed, but not text
  CHECK(p.fault == vn::Fault::kMalformed);
  CHECK_THAT(p.what, Catch::Contains("byte 8 is not text"));
  p = problemOf(line("VNYPR,+1.0,+2.0,+3.0,+4.0"));
  CHECK(p.fault == vn::Fault::kMalformed);
  CHECK_THAT(p.what, Catch::Contains("VNYPR with 4 values, not 3"));
}

TEST_CASE("vectornav names a NaN value", "[drivers][vectornav]") {
  auto p =
      problemOf(line("VNIMU,+00.2012,-00.0001,+00.4500,+0.0100,-0.0200,-9.8066,+0.0010,-0.0020,NaN,"
                     "+25.3,+101.325"));
  CHECK(p.fault == vn::Fault::kNotFinite);
  CHECK_THAT(p.what, Catch::Contains("value 9 (gyro z) 'NaN' is not finite"));
  p =
      problemOf(line("VNIMU,+00.2012,-00.0001,+00.4500,-inf,-0.0200,-9.8066,+0.0010,-0.0020,+0.5,"
                     "+25.3,+101.325"));
  CHECK(p.fault == vn::Fault::kNotFinite);
  CHECK_THAT(p.what, Catch::Contains("(accel x) '-inf'"));
}

TEST_CASE("vectornav names an empty line", "[drivers][vectornav]") {
  for (const std::string empty : {"", "$"}) {
    const auto p = problemOf(empty);
    CHECK(p.fault == vn::Fault::kMalformed);
    CHECK(p.what == "empty line");
  }
  const auto p = problemOf("$*00");
  CHECK(p.fault == vn::Fault::kMalformed);
  CHECK_THAT(p.what, Catch::Contains("empty message"));
}

TEST_CASE("vectornav names a wrong checksum", "[drivers][vectornav]") {
  const auto p = problemOf("$VNRRG,11*74");
  CHECK(p.fault == vn::Fault::kChecksum);
  CHECK_THAT(p.what, Catch::Contains("checksum 74, computed 73"));
  // One changed byte always changes an XOR checksum.
  std::string l = line(
      "VNIMU,+00.2012,-00.0001,+00.4500,+0.0100,-0.0200,-9.8066,+0.0010,"
      "-0.0020,-0.5000,+25.3,+101.325");
  l[40] = static_cast<char>(l[40] ^ 0x01);
  CHECK(problemOf(l).fault == vn::Fault::kChecksum);
}

TEST_CASE("vectornav turns the VN-100's y right, z down into REP-103", "[drivers][vectornav]") {
  vn::Sample s;
  s.gyro = {0.1, 0.2, -0.3};    // rolling right, pitching up, turning left (counter-clockwise)
  s.accel = {1.0, 2.0, -9.81};  // level and at rest the VN-100 reads -g on its z (down)
  const auto r = vn::toRep103(s);
  CHECK(r.gyro == std::array<double, 3>{0.1, -0.2, 0.3});
  CHECK(r.accel == std::array<double, 3>{1.0, -2.0, 9.81});
  CHECK(vn::fromRep103(r.gyro) == s.gyro);
}

TEST_CASE("vectornav splits lines from any chunks, skipping garbage and cut lines",
          "[drivers][vectornav]") {
  const std::string a = vn::frame("VNRRG,01,VN-100T-CR"), b = vn::frame("VNRRG,03,0100012345");
  std::string stream = "\x01zz\r\n";
  stream.append(a);
  stream.append("$VNYMR,+01");  // cut by the next '$'
  stream.append(b);
  std::mt19937 rng(5);
  for (int trial = 0; trial < 20; ++trial) {
    vn::LineSplitter splitter;
    std::vector<vn::LineSplitter::Line> lines;
    for (std::size_t at = 0; at < stream.size();) {
      const std::size_t n = std::min<std::size_t>(1 + rng() % 13, stream.size() - at);
      for (auto& l : splitter.feed(std::string_view(stream).substr(at, n))) lines.push_back(l);
      at += n;
    }
    REQUIRE(lines.size() == 3);
    CHECK(lines[0].text == a.substr(0, a.size() - 2));
    CHECK(lines[1].cut);
    CHECK(lines[2].text == b.substr(0, b.size() - 2));
    CHECK(splitter.skippedBytes() == 5);
  }
  // The tail: from the line's '$' to the end of the chunk it completed in.
  vn::LineSplitter splitter;
  CHECK(splitter.feed(a.substr(0, 10)).empty());
  const auto lines = splitter.feed(a.substr(10) + "xyz");
  REQUIRE(lines.size() == 1);
  CHECK(lines[0].tail == a.size() + 3);
}

/// Replies of a device to `command` (one framed line), as text lines.
std::vector<std::string> answers(VectorNavDevice& d, const std::string& command) {
  d.receive(command, 1000 * kMs);
  const std::string out = d.poll(1000 * kMs);
  std::vector<std::string> lines;
  vn::LineSplitter s;
  for (const auto& l : s.feed(out)) lines.push_back(l.text);
  return lines;
}

TEST_CASE("vectornav device answers and refuses as the manual says", "[drivers][vectornav]") {
  VectorNavDevice d;
  CHECK(answers(d, vn::readRegister(1)) == std::vector<std::string>{line("VNRRG,01,VN-100T-CR")});
  CHECK(answers(d, vn::readRegister(3)) == std::vector<std::string>{line("VNRRG,03,0100012345")});
  CHECK(answers(d, vn::writeRegister(7, "50")) == std::vector<std::string>{line("VNWRG,07,50")});
  CHECK(d.outputRate() == 50);
  CHECK(answers(d, "$VNRRG,07*XX\r\n") == std::vector<std::string>{line("VNRRG,07,50")});
  CHECK(answers(d, vn::writeRegister(7, "30")) == std::vector<std::string>{line("VNERR,07")});
  CHECK(answers(d, vn::writeRegister(6, "14")) == std::vector<std::string>{line("VNERR,07")});
  CHECK(answers(d, "$VNRRG,01*00\r\n") == std::vector<std::string>{line("VNERR,03")});
  CHECK(answers(d, vn::frame("VNXYZ,1")) == std::vector<std::string>{line("VNERR,04")});
  CHECK(answers(d, vn::frame("VNWRG,06")) == std::vector<std::string>{line("VNERR,05")});
  CHECK(answers(d, vn::frame("VNWRG,06,8,9")) == std::vector<std::string>{line("VNERR,06")});
  CHECK(answers(d, vn::readRegister(99)) == std::vector<std::string>{line("VNERR,08")});
  CHECK(answers(d, vn::writeRegister(1, "X")) == std::vector<std::string>{line("VNERR,09")});
  // VNIMU at 200 Hz is more than 115200 baud carries.
  CHECK(answers(d, vn::writeRegister(6, "19")) == std::vector<std::string>{line("VNWRG,06,19")});
  CHECK(answers(d, vn::writeRegister(7, "200")) == std::vector<std::string>{line("VNERR,12")});
  // The baud rate: the reply at the old rate, then the new one.
  CHECK(answers(d, vn::writeRegister(5, "230400")) ==
        std::vector<std::string>{line("VNWRG,05,230400")});
  CHECK(d.baud() == 230400);
  CHECK(answers(d, vn::writeRegister(5, "250000")) == std::vector<std::string>{line("VNERR,07")});
}

/// Session and device wired in memory on a simulated clock, with the baud rates of both ends:
/// at different rates each hears only noise. A reconnect opens the link 100 ms after it is asked.
struct Bench : tessera::test::SerialBench<Bench> {
  explicit Bench(VectorNavOptions o = {}, int session_baud = 115200, int device_baud = 115200)
      : device(device_baud), imu(o, session_baud) {
    reconnect_delay_ns = 100 * kMs;
  }
  VectorNavImu& session() { return imu; }
  int openBaud() const { return imu.openBaud(); }
  void collect(ImuOutput& out) {
    for (auto& s : out.samples) samples.push_back(s);
  }
  VectorNavDevice device;
  VectorNavImu imu;
  std::vector<ImuReading> samples;
};

TEST_CASE("vectornav session streams VNIMU at 100 Hz with REP-103 signs", "[drivers][vectornav]") {
  Bench b;
  b.device.motion().angular_velocity = {0.1, -0.2, 0.5};  // turning left at 0.5 rad/s
  b.connect();
  b.run(1000 * kMs);
  REQUIRE(b.imu.streaming());
  CHECK(b.device.outputType() == vn::kTypeImu);
  CHECK(b.device.outputRate() == 100);
  CHECK(b.imu.model() == "VN-100T-CR, serial 0100012345");
  const std::size_t before = b.samples.size();
  b.run(1000 * kMs);
  CHECK(b.samples.size() - before >= 99);
  CHECK(b.samples.size() - before <= 101);
  for (const auto& s : b.samples) {
    CHECK(s.gyro == std::array<double, 3>{0.1, -0.2, 0.5});
    CHECK(s.accel[2] == Approx(9.80665).margin(1e-4));
    CHECK(s.accel[0] == 0);
  }
  // Stamped when the line began: its transfer time at 115200 baud before it was read (each line
  // is read alone here: 110 bytes of 10 bits, 9.55 ms).
  REQUIRE(b.device.linesSkipped() == 0);
  for (std::size_t k = 1; k < b.samples.size(); ++k) {
    CHECK(b.samples[k].stamp_ns > b.samples[k - 1].stamp_ns);
    CHECK(b.samples[k].received_ns - b.samples[k].stamp_ns == 9'548'611);
  }
  CHECK(b.reconnects == 0);
  CHECK(b.imu.counters().badLines() == 0);
}

TEST_CASE("vectornav session finds the device at another rate and switches it",
          "[drivers][vectornav]") {
  VectorNavOptions o;
  o.output = vn::Output::kYmr;
  SECTION("at the factory 115200, switched to 230400 for VNYMR at 100 Hz") {
    Bench b(o, 230400, 115200);
    b.device.motion().angular_velocity = {0, 0, -0.25};
    b.connect();
    b.run(2000 * kMs);
    REQUIRE(b.imu.streaming());
    CHECK(b.said("no reply at 230400 baud; trying 115200"));
    CHECK(b.device.baud() == 230400);
    CHECK(b.link_baud == 230400);
    CHECK(b.device.outputType() == vn::kTypeYmr);
    REQUIRE(b.samples.size() > 50);
    CHECK(b.samples.back().gyro[2] == Approx(-0.25));
    CHECK(b.reconnects == 0);  // searched in place, without reopening the port
  }
  SECTION("at 921600, the last rate searched") {
    Bench b(o, 460800, 921600);
    b.connect();
    b.run(4000 * kMs);
    REQUIRE(b.imu.streaming());
    CHECK(b.said("trying 921600"));
    CHECK(b.device.baud() == 460800);
  }
  SECTION("nowhere: a reconnect after every rate") {
    Bench b(o, 230400, 115200);
    b.device.faults().silent = true;
    b.connect();
    b.run(3000 * kMs);
    CHECK(b.reconnects == 1);
    CHECK_THAT(b.reason, Catch::Contains("at any baud rate"));
  }
}

TEST_CASE("vectornav session ends on a VNERR reply, naming its code", "[drivers][vectornav]") {
  VectorNavImu imu({}, 115200);
  (void)imu.connected(0);
  auto out = imu.received(vn::frame("VNRRG,01,VN-100T-CR"), kMs);
  CHECK(out.send == vn::readRegister(3));
  out = imu.received(vn::frame("VNRRG,03,0100012345"), 2 * kMs);
  CHECK(out.send == vn::writeRegister(6, "19"));
  out = imu.received(vn::frame("VNERR,12"), 3 * kMs);
  REQUIRE(out.reconnect);
  CHECK(out.reconnect_reason ==
        "the VN-100 refused set output type (VNWRG,06,19): error 12 (insufficient baud rate)");
  CHECK(imu.counters().device_errors == 1);
  // While streaming, an error is logged, not a reason to reconnect.
  (void)imu.connected(10 * kMs);
  for (const auto& reply : {"VNRRG,01,VN-100T-CR", "VNRRG,03,1", "VNWRG,06,19", "VNWRG,07,100"})
    (void)imu.received(vn::frame(reply), 11 * kMs);
  REQUIRE(imu.streaming());
  out = imu.received(vn::frame("VNERR,11"), 12 * kMs);
  CHECK_FALSE(out.reconnect);
  CHECK(out.events ==
        std::vector<std::string>{"the VN-100 reports error 11 (output buffer overflow)"});
  // A reply that is not the one asked for ends the session too.
  (void)imu.connected(20 * kMs);
  (void)imu.received(vn::frame("VNRRG,01,VN-100T-CR"), 21 * kMs);
  (void)imu.received(vn::frame("VNRRG,03,1"), 21 * kMs);
  out = imu.received(vn::frame("VNWRG,06,8"), 22 * kMs);
  CHECK(out.reconnect);
  CHECK_THAT(out.reconnect_reason, Catch::Contains("with '8'"));
}

TEST_CASE("vectornav session drops NaN, truncated and corrupt lines", "[drivers][vectornav]") {
  VectorNavImu imu({}, 115200);
  (void)imu.connected(0);
  for (const auto& reply : {"VNRRG,01,VN-100T-CR", "VNRRG,03,1", "VNWRG,06,19", "VNWRG,07,100"})
    (void)imu.received(vn::frame(reply), kMs);
  REQUIRE(imu.streaming());
  const std::string good =
      "VNIMU,+00.2012,-00.0001,+00.4500,+0.0100,-0.0200,-9.8066,+0.0010,-0.0020,-0.5000,+25.3,"
      "+101.325";
  std::string nan = good;
  nan.replace(nan.find("-0.5000"), 7, "NaN");
  std::string corrupt = vn::frame(good);
  corrupt[30] = '7';
  const std::string stream = vn::frame(nan) + "$VNIMU,+00.2" + corrupt + vn::frame(good);
  const auto out = imu.received(stream, 2 * kMs);
  REQUIRE(out.samples.size() == 1);
  CHECK(out.samples[0].gyro[2] == 0.5);
  const auto c = imu.counters();
  CHECK(c.not_finite == 1);
  CHECK(c.truncated == 1);
  CHECK(c.bad_checksum == 1);
  CHECK(out.events.size() == 3);
}

TEST_CASE("vectornav session never returns damaged lines", "[drivers][vectornav]") {
  Bench b;
  b.device.motion().angular_velocity = {0, 0, 0.5};
  b.device.motion().specific_force = {0.5, -0.25, 9.75};
  b.connect();
  b.run(500 * kMs);
  REQUIRE(b.imu.streaming());
  b.device.faults().garbage_probability = 0.3;
  b.device.faults().corrupt_probability = 0.3;
  b.run(3000 * kMs);
  for (const auto& s : b.samples) {
    CHECK(s.gyro == std::array<double, 3>{0, 0, 0.5});
    CHECK(s.accel == std::array<double, 3>{0.5, -0.25, 9.75});
  }
  const auto c = b.imu.counters();
  CHECK(c.badLines() > 20);
  CHECK(c.bad_checksum + c.truncated > 0);
  CHECK(c.garbage_bytes > 0);
  CHECK(b.samples.size() > 150);  // the undamaged ones all came through
}

TEST_CASE("vectornav session waits for late replies and sends commands again",
          "[drivers][vectornav]") {
  Bench b;
  b.device.faults().reply_delay_s = 0.2;  // within reply_timeout_s (0.3)
  b.connect();
  b.run(2000 * kMs);
  CHECK(b.imu.streaming());
  CHECK_FALSE(b.said("sending it again"));
  Bench c;
  c.device.faults().reply_delay_s = 0.45;  // each reply after the command was sent again
  c.connect();
  c.run(4000 * kMs);
  CHECK(c.imu.streaming());
  CHECK(c.said("sending it again"));
  CHECK(c.reconnects == 0);
}

TEST_CASE("vectornav session reconnects to a device gone silent", "[drivers][vectornav]") {
  Bench b;
  b.connect();
  b.run(500 * kMs);
  REQUIRE(b.imu.streaming());
  b.device.faults().silent = true;
  b.run(300 * kMs);
  CHECK(b.reconnects == 1);
  CHECK(b.reason == "no good sample for 0.2 s (20 periods at 100 Hz)");
  b.device.faults().silent = false;
  const std::size_t before = b.samples.size();
  b.run(1000 * kMs);
  CHECK(b.imu.streaming());
  CHECK(b.imu.counters().sessions == 2);
  CHECK(b.samples.size() > before + 50);
}

TEST_CASE("vectornav session refuses options the VN-100 does not have", "[drivers][vectornav]") {
  VectorNavOptions o;
  o.rate_hz = 30;
  CHECK_THROWS_WITH(VectorNavImu(o, 115200), Catch::Contains("rate_hz") && Catch::Contains("30"));
  o = {};
  CHECK_THROWS_WITH(VectorNavImu(o, 128000),
                    Catch::StartsWith("baud") && Catch::Contains("128000"));
  o.output = vn::Output::kYmr;  // VNYMR lines at 100 Hz are more than 115200 baud carries
  CHECK_THROWS_WITH(VectorNavImu(o, 115200), Catch::Contains("cannot carry"));
  CHECK_NOTHROW(VectorNavImu(o, 230400));
  o = {};
  o.silence_periods = 0;
  CHECK_THROWS_WITH(VectorNavImu(o, 115200), Catch::Contains("silence_periods"));
  o = {};
  o.reply_timeout_s = std::nan("");
  CHECK_THROWS_WITH(VectorNavImu(o, 115200), Catch::Contains("reply_timeout_s"));
}

}  // namespace vectornav_test
