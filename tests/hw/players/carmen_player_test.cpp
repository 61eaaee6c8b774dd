#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/players/carmen_player.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>

#include <cmath>
#include <fstream>
#include <numbers>

#include "../../shared_data.hpp"

using namespace tessera;
using Catch::Matchers::Contains;
using tessera::players::CarmenPlayer;
using tessera::players::CarmenPlayerOptions;
namespace fs = std::filesystem;

namespace {

std::string flaser(double t, double x, const std::string& r0 = "1.5") {
  return "FLASER 3 " + r0 + " 81.83 2.0 " + std::to_string(x) + " 0 0 " + std::to_string(x) +
         " 0 0 " + std::to_string(t) + " host " + std::to_string(t) + "\n";
}

fs::path writeLog(const std::string& name, const std::string& text) {
  const fs::path path = tessera::test::scratchDir("carmen_player") / name;
  std::ofstream(path) << text;
  return path;
}

CarmenPlayerOptions optionsFor(const fs::path& path) {
  CarmenPlayerOptions o;
  o.path = path.string();
  return o;
}

std::int64_t summaryInt(const Actor& a, const char* key) {
  Summary s;
  a.summarize(s);
  return std::get<std::int64_t>(s.at(key));
}

std::string summaryString(const Actor& a, const char* key) {
  Summary s;
  a.summarize(s);
  return std::get<std::string>(s.at(key));
}

std::string configErrorOf(const CarmenPlayerOptions& o) {
  try {
    CarmenPlayer p(o);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("carmen_player publishes each record at its log time, stamped with the log's time",
          "[players][carmen]") {
  const auto path = writeLog("a.log", "# log\nPARAM x 1\n" + flaser(1000.0, 0.0) +
                                          flaser(1000.5, 1.0) + "NEFF 3\n" + flaser(1002.0, 2.0));
  ActorHarness h(std::make_unique<CarmenPlayer>(optionsFor(path)));
  h.advance(0);  // the first record is due at once
  CHECK(h.publishedCount("scan") == 1);
  h.advance(kNanosPerSecond / 2 - 1);
  CHECK(h.publishedCount("scan") == 1);
  h.advance(1);  // runtime 0.5 s = log 1000.5 s
  CHECK(h.publishedCount("scan") == 2);
  h.advance(2 * kNanosPerSecond);
  REQUIRE(h.publishedCount("scan") == 3);

  const auto scans = h.published<msg::LaserScan>("scan");
  const auto odom = h.published<msg::Odometry>("odom");
  REQUIRE(odom.size() == 3);  // no ODOM lines: the laser lines' odometry pose
  CHECK(scans[0]->getHeader().getStampNs() == 1000 * kNanosPerSecond);
  CHECK(scans[1]->getHeader().getStampNs() == 1000 * kNanosPerSecond + kNanosPerSecond / 2);
  CHECK(scans[2]->getHeader().getStampNs() == 1002 * kNanosPerSecond);
  const auto r = view<float>(scans[0]->getRanges());
  REQUIRE(r.size() == 3);
  CHECK(r[0] == 1.5f);
  CHECK(std::isinf(r[1]));  // 81.83 m = no return
  CHECK(r[2] == 2.0f);
  CHECK(scans[0]->getAngleMin() == Approx(-std::numbers::pi / 2));
  CHECK(scans[0]->getAngleIncrement() == Approx(std::numbers::pi / 2));  // odd n: both ends
  CHECK(scans[0]->getRangeMax() == 80.0f);
  CHECK(std::string(scans[0]->getHeader().getFrameId().cStr()) == "laser");
  for (std::size_t i = 0; i < 3; ++i) {
    CHECK(odom[i]->getHeader().getStampNs() == scans[i]->getHeader().getStampNs());
    CHECK(odom[i]->getPose().getX() == Approx(static_cast<double>(i)));
  }
  CHECK(odom[1]->getTwist().getVx() == Approx(2.0));  // 1 m in 0.5 s
  CHECK(summaryInt(h.actor(), "scans_published") == 3);
  CHECK(summaryInt(h.actor(), "lines_skipped") == 2);
  CHECK(summaryString(h.actor(), "skipped") == "NEFF: 1, PARAM: 1");
  CHECK(summaryString(h.actor(), "odometry_source") == "laser");
  CHECK(summaryString(h.actor(), "error").empty());
}

TEST_CASE("carmen_player takes odometry from ODOM lines when the log has them",
          "[players][carmen]") {
  const auto path =
      writeLog("b.log", "ODOM 0.5 0 0 0.2 0.1 0 10.0 h 10.0\n" + flaser(10.1, 7.0) +
                            "ODOM 0.6 0 0 0.2 0.1 0 10.2 h 10.2\n" + flaser(10.3, 8.0));
  auto o = optionsFor(path);
  o.publish_reference = true;
  o.laser_mount = {0.5, 0, 0};
  o.relative_stamps = true;
  ActorHarness h(std::make_unique<CarmenPlayer>(o));
  h.advance(kNanosPerSecond);
  const auto odom = h.published<msg::Odometry>("odom");
  const auto gt = h.published<msg::GroundTruthPose>("ground_truth");
  REQUIRE(odom.size() == 2);
  CHECK(odom[0]->getPose().getX() == 0.5);
  CHECK(odom[0]->getTwist().getVx() == 0.2);
  CHECK(odom[0]->getTwist().getOmega() == 0.1);
  CHECK(odom[0]->getHeader().getStampNs() == 0);  // relative stamps: runtime time
  CHECK(odom[1]->getHeader().getStampNs() == 200'000'000);
  REQUIRE(gt.size() == 2);
  // The laser line's pose is the laser's; the reference is base_link, 0.5 m behind it.
  CHECK(gt[0]->getPose().getX() == Approx(6.5));
  CHECK(gt[0]->getHeader().getStampNs() == 100'000'000);
  CHECK(h.published<msg::LaserScan>("scan")[0]->getMountX() == 0.5f);
  CHECK(summaryString(h.actor(), "odometry_source") == "odom");
}

TEST_CASE("carmen_player stops the run with file:line on a malformed line, or skips it",
          "[players][carmen]") {
  const auto path = writeLog("bad.log", flaser(1.0, 0) + flaser(2.0, 0, "nan") + flaser(3.0, 0));
  {
    ActorHarness h(std::make_unique<CarmenPlayer>(optionsFor(path)));
    h.advance(10 * kNanosPerSecond);
    CHECK(h.publishedCount("scan") == 1);
    const std::string reason = h.runtime().report().stop_reason;
    CHECK_THAT(reason, Contains("carmen_player"));
    CHECK_THAT(reason, Contains("bad.log:2:"));
    CHECK_THAT(summaryString(h.actor(), "error"), Contains("expected a finite number, got 'nan'"));
  }
  {
    auto o = optionsFor(path);
    o.skip_malformed = true;
    ActorHarness h(std::make_unique<CarmenPlayer>(o));
    h.advance(10 * kNanosPerSecond);
    CHECK(h.publishedCount("scan") == 2);
    CHECK(h.runtime().report().stop_reason.empty());
    CHECK(summaryInt(h.actor(), "lines_skipped") == 1);
  }
}

TEST_CASE("carmen_player honours start_time, end_time and max_scans", "[players][carmen]") {
  std::string text;
  for (int i = 0; i < 10; ++i) text += flaser(50.0 + i, i);
  const auto path = writeLog("c.log", text);
  auto o = optionsFor(path);
  o.start_time = 2.0;
  o.end_time = 6.5;
  o.relative_stamps = true;
  ActorHarness h(std::make_unique<CarmenPlayer>(o));
  h.advance(20 * kNanosPerSecond);
  const auto scans = h.published<msg::LaserScan>("scan");
  REQUIRE(scans.size() == 5);  // t = 52 .. 56
  // The runtime origin is the first published record (t = 52), not the first line.
  CHECK(scans.front()->getHeader().getStampNs() == 0);
  CHECK(scans.back()->getHeader().getStampNs() == 4 * kNanosPerSecond);

  auto m = optionsFor(path);
  m.max_scans = 3;
  ActorHarness h2(std::make_unique<CarmenPlayer>(m));
  h2.advance(20 * kNanosPerSecond);
  CHECK(h2.publishedCount("scan") == 3);
}

TEST_CASE("carmen_player rejects bad options with the option's name", "[players][carmen]") {
  CHECK_THAT(configErrorOf(CarmenPlayerOptions{}), Contains("option 'path': is required"));
  auto o = optionsFor("/nonexistent/x.clf");
  CHECK_THAT(configErrorOf(o), Contains("not a readable file"));
  const auto path = writeLog("d.log", flaser(1, 0));
  o = optionsFor(path);
  o.laser = "SONAR";
  CHECK_THAT(configErrorOf(o), Contains("option 'laser'"));
  o = optionsFor(path);
  o.odometry = "gps";
  CHECK_THAT(configErrorOf(o), Contains("option 'odometry'"));
  o = optionsFor(path);
  o.laser_mount = {1, 2};
  CHECK_THAT(configErrorOf(o), Contains("option 'laser_mount'"));
  o = optionsFor(path);
  o.end_time = 1;
  o.start_time = 2;
  CHECK_THAT(configErrorOf(o), Contains("option 'end_time'"));
  CHECK(configErrorOf(optionsFor(path)).empty());
}

TEST_CASE("carmen_player replays intel.clf: 2726 scans with raw odometry", "[players][carmen]") {
  TESSERA_SHARED_DATA(path, "intel-lab-mrpt/intel.clf.gz");
  ActorHarness h(std::make_unique<CarmenPlayer>(optionsFor(path)));
  h.advance(3000 * kNanosPerSecond);
  const auto scans = h.published<msg::LaserScan>("scan");
  const auto odom = h.published<msg::Odometry>("odom");
  REQUIRE(scans.size() == 2726);
  REQUIRE(odom.size() == 2726);
  CHECK(scans.front()->getHeader().getStampNs() == 976052856'338882000);
  CHECK(scans.back()->getHeader().getStampNs() == 976055550'147778000);
  CHECK(odom.back()->getPose().getX() == Approx(-50.795746));
  CHECK(summaryString(h.actor(), "error").empty());
}

TEST_CASE("carmen_player replays the GMapping-corrected log with ODOM and reference poses",
          "[players][carmen]") {
  TESSERA_SHARED_DATA(path, "intel-lab-carmen-gfs/intel-corrected.log.gz");
  auto o = optionsFor(path);
  o.publish_reference = true;
  ActorHarness h(std::make_unique<CarmenPlayer>(o));
  h.advance(3000 * kNanosPerSecond);
  CHECK(h.publishedCount("scan") == 910);
  CHECK(h.publishedCount("ground_truth") == 910);
  CHECK(h.publishedCount("odom") == 14541 - 863);
  CHECK(summaryInt(h.actor(), "lines_skipped") == 912 + 863);
  // ODOM ipc timestamps in this log jitter backwards by up to ~1 s; they are kept and counted.
  CHECK(summaryInt(h.actor(), "time_reversals") > 0);
  CHECK(summaryString(h.actor(), "error").empty());
}

TEST_CASE("carmen_player stamps scans from a scan_times file when the log repeats stamps",
          "[players][carmen]") {
  // All files in one folder: writeLog() starts a fresh folder each time.
  const fs::path dir = tessera::test::scratchDir("carmen_scan_times");
  const auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name) << text;
    return dir / name;
  };
  const auto path =
      write("dup.log", flaser(1000.0, 0.0) + flaser(1000.0, 1.0) + flaser(1000.0, 2.0));
  const auto times = write("times.txt", "0 1000.0 1\n1 1000.25 0\n2 1000.5 0\n");
  CarmenPlayerOptions o = optionsFor(path);
  o.scan_times = times.string();
  ActorHarness h(std::make_unique<CarmenPlayer>(o));
  h.advance(kNanosPerSecond);
  const auto scans = h.published<msg::LaserScan>("scan");
  const auto odom = h.published<msg::Odometry>("odom");
  REQUIRE(scans.size() == 3);
  REQUIRE(odom.size() == 3);
  for (std::size_t i = 0; i < 3; ++i) {
    const Nanos expected = 1000 * kNanosPerSecond + static_cast<Nanos>(i) * kNanosPerSecond / 4;
    CHECK(scans[i]->getHeader().getStampNs() == expected);
    CHECK(odom[i]->getHeader().getStampNs() == expected);
  }

  // Fewer times than laser lines: the run stops naming the times file.
  const auto short_times = write("short.txt", "0 1000.0 1\n1 1000.25 0\n");
  o.scan_times = short_times.string();
  ActorHarness h2(std::make_unique<CarmenPlayer>(o));
  h2.advance(kNanosPerSecond);
  CHECK(h2.publishedCount("scan") == 2);
  CHECK_THAT(summaryString(h2.actor(), "error"), Contains("short.txt") && Contains("more"));

  // Out of order or malformed: refused at configuration with the option's name.
  o.scan_times = write("bad.txt", "0 1000.0 1\n1 999.0 0\n").string();
  CHECK_THAT(configErrorOf(o), Contains("scan_times") && Contains("bad.txt:2"));
  o.scan_times = write("garbage.txt", "0 1000.0 1\nzero x\n").string();
  CHECK_THAT(configErrorOf(o), Contains("scan_times") && Contains("garbage.txt:2"));
  o.scan_times = write("empty.txt", "# nothing\n").string();
  CHECK_THAT(configErrorOf(o), Contains("holds no times"));
}
