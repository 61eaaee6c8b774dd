#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/players/urg_player.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>

#include <cmath>
#include <fstream>
#include <numbers>

#include "../../shared_data.hpp"

using namespace tessera;
using Catch::Matchers::Contains;
using tessera::players::UrgPlayer;
using tessera::players::UrgPlayerOptions;
namespace fs = std::filesystem;

namespace {

std::string urgLine(std::int64_t t_us, std::int64_t left, std::int64_t right,
                    const std::string& first_range = "1000") {
  std::string s = std::to_string(t_us) + " 0 " + std::to_string(left) + " " + std::to_string(right);
  for (int i = 0; i < 20; ++i) s += " 0";
  s += " " + first_range;
  for (int k = 1; k < 682; ++k) s += k % 2 ? " 0" : " 1500";
  return s + " 0\n";
}

UrgPlayerOptions optionsFor(const fs::path& path) {
  UrgPlayerOptions o;
  o.path = path.string();
  return o;
}

Summary summaryOf(const Actor& a) {
  Summary s;
  a.summarize(s);
  return s;
}

}  // namespace

TEST_CASE("urg_player publishes dead-reckoned odometry then the scan of each line",
          "[players][urg]") {
  const fs::path path = tessera::test::scratchDir("urg_player") / "exp.dat";
  // 2000 ticks = one wheel turn = 2 pi 0.077 m; the third line turns in place (half a turn of
  // each wheel, in opposite directions, 0.33 m apart).
  std::ofstream(path) << urgLine(5'000'000, 100, 100) + urgLine(5'100'000, 2100, 2100) +
                             urgLine(5'200'000, 1100, 3100, "7");
  ActorHarness h(std::make_unique<UrgPlayer>(optionsFor(path)));
  h.advance(0);
  CHECK(h.publishedCount("scan") == 1);
  h.advance(kNanosPerSecond);
  const auto scans = h.published<msg::LaserScan>("scan");
  const auto odom = h.published<msg::Odometry>("odom");
  REQUIRE(scans.size() == 3);
  REQUIRE(odom.size() == 3);
  const double turn = 2 * std::numbers::pi * 0.077;
  CHECK(odom[0]->getPose().getX() == 0);
  CHECK(odom[1]->getPose().getX() == Approx(turn));
  CHECK(odom[1]->getTwist().getVx() == Approx(turn / 0.1));
  CHECK(odom[2]->getPose().getX() == Approx(turn));
  CHECK(odom[2]->getPose().getTheta() == Approx(turn / 0.33));
  CHECK(scans[1]->getHeader().getStampNs() == 5'100'000'000);
  CHECK(odom[1]->getHeader().getStampNs() == 5'100'000'000);
  const auto r = view<float>(scans[2]->getRanges());
  REQUIRE(r.size() == 682);
  CHECK(std::isnan(r[0]));  // error code 7
  CHECK(std::isinf(r[1]));  // 0 = no return
  CHECK(r[2] == 1.5f);
  CHECK(scans[0]->getMountX() == Approx(0.145f));
  CHECK(scans[0]->getAngleMin() == Approx(-120 * std::numbers::pi / 180));
  CHECK(std::get<std::int64_t>(summaryOf(h.actor()).at("scans_published")) == 3);
}

TEST_CASE("urg_player stops the run on a malformed line and names it", "[players][urg]") {
  const fs::path path = tessera::test::scratchDir("urg_player_bad") / "exp.dat";
  std::ofstream(path) << urgLine(1'000'000, 0, 0) + "1100000 0 5 5 truncated\n" +
                             urgLine(1'200'000, 0, 0);
  ActorHarness h(std::make_unique<UrgPlayer>(optionsFor(path)));
  h.advance(kNanosPerSecond);
  CHECK(h.publishedCount("scan") == 1);
  CHECK_THAT(h.runtime().report().stop_reason, Contains("exp.dat:2:"));
  CHECK_THAT(h.runtime().report().stop_reason, Contains("urg_player"));

  auto o = optionsFor(path);
  o.skip_malformed = true;
  ActorHarness lenient(std::make_unique<UrgPlayer>(o));
  lenient.advance(kNanosPerSecond);
  CHECK(lenient.publishedCount("scan") == 2);
  CHECK(std::get<std::int64_t>(summaryOf(lenient.actor()).at("lines_skipped")) == 1);
}

TEST_CASE("urg_player rejects a missing path and bad robot parameters", "[players][urg]") {
  const auto error = [](const UrgPlayerOptions& o) -> std::string {
    try {
      UrgPlayer p(o);
    } catch (const ConfigError& e) {
      return e.what();
    }
    return "";
  };
  CHECK_THAT(error(UrgPlayerOptions{}), Contains("option 'path': is required"));
  const fs::path path = tessera::test::scratchDir("urg_player_opts") / "exp.dat";
  std::ofstream(path) << urgLine(0, 0, 0);
  auto o = optionsFor(path);
  o.wheel_radius = 0;
  CHECK_THAT(error(o), Contains("option 'wheel_radius'"));
  o = optionsFor(path);
  o.ticks_per_revolution = -1;
  CHECK_THAT(error(o), Contains("option 'ticks_per_revolution'"));
  CHECK(error(optionsFor(path)).empty());
}

TEST_CASE("urg_player replays MinesParisTech exp2: 641 scans, ~44.5 m of odometry",
          "[players][urg]") {
  TESSERA_SHARED_DATA(path, "mines-paristech-urg04lx-odometry/exp2.dat.gz");
  ActorHarness h(std::make_unique<UrgPlayer>(optionsFor(path)));
  h.advance(100 * kNanosPerSecond);
  CHECK(h.publishedCount("scan") == 641);
  CHECK(h.publishedCount("odom") == 641);
  const auto s = summaryOf(h.actor());
  CHECK(std::get<double>(s.at("distance_m")) == Approx(44.50).margin(0.02));
  CHECK(std::get<std::string>(s.at("error")).empty());
  CHECK(h.published<msg::Odometry>("odom").back()->getHeader().getStampNs() == 424'593'575'000);
}
