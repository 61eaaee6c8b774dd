// `tessera bench matcher`: the correlative matcher's branch and bound against exhaustive search
// on the same candidates. A map of the built-in office is made by ray casting scans into an
// OccupancyGrid; probe scans from random free poses are matched from initial guesses offset
// within the window, and both searches are timed on each (same machine, same run).
#include "bench_commands.hpp"

#include <tessera/grid/occupancy_grid.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/scan_matching/correlative_matcher.hpp>
#include <tessera/sim/ray_caster.hpp>
#include <tessera/sim/world.hpp>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <memory>
#include <numbers>
#include <random>

namespace tessera::app {
namespace {

struct Options {
  int scans = 5;
  double linear = 3.5;    // [m] half-width
  double angular = 15.0;  // [deg] half-width
  double offset = 3.0;    // [m] largest initial error per axis
  double range = 12.0;    // [m] laser range
  int beams = 360;        // full circle
  int depth = 7;
  std::uint64_t seed = 1;
  bool exhaustive = true;
  bool json = false;
};

double seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// A free pose at least `clearance` from any wall.
tessera::Pose2 randomFreePose(const sim::World& w, std::mt19937_64& rng, double clearance) {
  std::uniform_real_distribution<double> ux(0.0, w.widthMeters()), uy(0.0, w.heightMeters()),
      ut(-std::numbers::pi, std::numbers::pi);
  for (;;) {
    const tessera::Pose2 p{ux(rng), uy(rng), ut(rng)};
    if (!w.blocked(p.translation()) && w.clearance(p.translation(), clearance) >= clearance)
      return p;
  }
}

}  // namespace

void addBenchMatcherCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "matcher",
      "correlative scan-to-grid matcher: branch and bound vs exhaustive search on the built-in "
      "office (time per scan, candidates scored, pose error)");
  auto o = std::make_shared<Options>();
  cmd->add_option("--scans", o->scans, "probe scans")->capture_default_str();
  cmd->add_option("--linear", o->linear, "search window half-width [m]")->capture_default_str();
  cmd->add_option("--angular", o->angular, "search window half-width [deg]")->capture_default_str();
  cmd->add_option("--offset", o->offset, "largest initial error per axis [m] (heading: the window)")
      ->capture_default_str();
  cmd->add_option("--range", o->range, "laser range [m]")->capture_default_str();
  cmd->add_option("--beams", o->beams, "beams over 360 deg")->capture_default_str();
  cmd->add_option("--depth", o->depth, "pyramid depth")->capture_default_str();
  cmd->add_option("--seed", o->seed, "random seed")->capture_default_str();
  cmd->add_flag("!--no-exhaustive", o->exhaustive, "skip the (slow) exhaustive search");
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    if (o->scans < 1) throw ConfigError("--scans must be >= 1");
    if (!(o->linear > 0.0) || !(o->angular >= 0.0) || !(o->range > 0.0) || o->beams < 8)
      throw ConfigError("--linear, --range must be > 0, --angular >= 0, --beams >= 8");
    if (!(o->offset >= 0.0 && o->offset <= o->linear))
      throw ConfigError("--offset must be in [0, --linear]");
    const sim::World world = sim::World::builtinOffice();
    // A full circle with the first beam straight ahead: the centred sweep (first beam at -pi)
    // on a laser turned by pi.
    sim::LaserConfig laser;
    laser.fov = 2.0 * std::numbers::pi;
    laser.beams = o->beams;
    laser.range_max = o->range;
    laser.mount.theta = std::numbers::pi;
    const double angle_min = laser.mount.theta + laser.angleMin();  // 0 in base_link
    const double angle_increment = laser.angleIncrement();
    const sim::LaserModel model(world, laser);
    std::mt19937_64 rng(o->seed);

    // The map: scans from free poses on a 2 m lattice.
    auto t0 = std::chrono::steady_clock::now();
    tessera::grid::OccupancyGrid grid;
    int mapping_scans = 0;
    for (double y = 1.0; y < world.heightMeters(); y += 2.0)
      for (double x = 1.0; x < world.widthMeters(); x += 2.0) {
        const tessera::Pose2 p{x, y, 0.0};
        if (world.blocked(p.translation()) || world.clearance(p.translation(), 0.3) < 0.3) continue;
        const auto ranges = model.scan(p, rng);
        grid.insertScan({ranges, angle_min, angle_increment, laser.range_min, laser.range_max},
                        {p.x, p.y, p.theta}, {o->range, o->range});
        ++mapping_scans;
      }
    const tessera::grid::OccupancyMap map = grid.toOccupancyMap();
    const double map_s = seconds(t0);

    tessera::scan_matching::CorrelativeMatcherOptions mo;
    mo.pyramid_depth = o->depth;
    const tessera::scan_matching::CorrelativeMatcher bnb(mo);
    mo.search = tessera::scan_matching::CorrelativeMatcherOptions::Search::kExhaustive;
    const tessera::scan_matching::CorrelativeMatcher exhaustive(mo);
    t0 = std::chrono::steady_clock::now();
    const tessera::scan_matching::MatchGrid pyramid =
        bnb.precompute(tessera::scan_matching::GridView::of(map));
    const double precompute_s = seconds(t0);

    const tessera::scan_matching::SearchWindow window{o->linear,
                                                      o->angular * std::numbers::pi / 180.0};
    std::uniform_real_distribution<double> off(-o->offset, o->offset),
        turn(-window.angular, window.angular);
    nlohmann::json runs = nlohmann::json::array();
    double bnb_total = 0.0, ex_total = 0.0;
    for (int k = 0; k < o->scans; ++k) {
      const tessera::Pose2 truth = randomFreePose(world, rng, 0.4);
      const auto ranges = model.scan(truth, rng);
      std::vector<Eigen::Vector2d> pts;
      for (int b = 0; b < o->beams; ++b) {
        const double r = ranges[static_cast<std::size_t>(b)];
        if (!std::isfinite(r)) continue;
        const double a = angle_min + b * angle_increment;
        pts.emplace_back(r * std::cos(a), r * std::sin(a));
      }
      const tessera::Pose2 t(truth.x, truth.y, truth.theta);
      const tessera::Pose2 initial(t.x + off(rng), t.y + off(rng), t.theta + turn(rng));
      t0 = std::chrono::steady_clock::now();
      const auto r = bnb.match(pyramid, pts, initial, window);
      const double bnb_s = seconds(t0);
      bnb_total += bnb_s;
      nlohmann::json run{{"points", pts.size()},
                         {"status", tessera::scan_matching::toString(r.status)},
                         {"score", r.score},
                         {"second_best", r.second_best_score},
                         {"error_m", (r.pose.translation() - t.translation()).norm()},
                         {"error_deg", std::abs(tessera::angleDiff(r.pose.theta, t.theta)) * 180.0 /
                                           std::numbers::pi},
                         {"angular_step_deg", r.angular_step * 180.0 / std::numbers::pi},
                         {"bnb_s", bnb_s},
                         {"bnb_scored", r.nodes_scored}};
      if (o->exhaustive) {
        t0 = std::chrono::steady_clock::now();
        const auto e = exhaustive.match(pyramid, pts, initial, window);
        const double ex_s = seconds(t0);
        ex_total += ex_s;
        run["exhaustive_s"] = ex_s;
        run["exhaustive_scored"] = e.nodes_scored;
        run["same_score"] = e.score == r.score;
      }
      if (!o->json) std::cerr << "[bench matcher] scan " << k + 1 << "/" << o->scans << " done\n";
      runs.push_back(run);
    }

    const nlohmann::json setup{
        {"world", "builtin:office"},
        {"map_cells", std::to_string(map.width) + "x" + std::to_string(map.height)},
        {"resolution", map.resolution},
        {"mapping_scans", mapping_scans},
        {"map_s", map_s},
        {"precompute_s", precompute_s},
        {"depth", pyramid.depth()},
        {"window_linear_m", o->linear},
        {"window_angular_deg", o->angular},
        {"beams", o->beams},
        {"range_m", o->range}};
    if (o->json) {
      std::cout << nlohmann::json{{"machine", machineDescription()},
                                  {"setup", setup},
                                  {"runs", runs},
                                  {"bnb_mean_s", bnb_total / o->scans},
                                  {"exhaustive_mean_s", ex_total / o->scans}}
                       .dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << "map: builtin office, " << map.width << "x" << map.height << " cells at "
              << map.resolution << " m (" << mapping_scans << " scans, " << std::fixed
              << std::setprecision(2) << map_s << " s); pyramid depth " << pyramid.depth()
              << " built in " << std::setprecision(3) << precompute_s << " s\n"
              << "window: +-" << o->linear << " m, +-" << o->angular << " deg; " << o->beams
              << " beams, range " << o->range << " m\n\n"
              << std::setw(6) << "points" << std::setw(8) << "score" << std::setw(8) << "2nd"
              << std::setw(9) << "err m" << std::setw(9) << "err deg" << std::setw(10) << "BnB ms"
              << std::setw(11) << "BnB nodes" << std::setw(12) << "exhaust ms" << std::setw(13)
              << "exh. nodes" << std::setw(7) << "same\n";
    for (const auto& r : runs) {
      std::cout << std::setw(6) << r["points"].get<std::size_t>() << std::setprecision(3)
                << std::setw(8) << r["score"].get<double>() << std::setw(8)
                << r["second_best"].get<double>() << std::setw(9) << r["error_m"].get<double>()
                << std::setprecision(2) << std::setw(9) << r["error_deg"].get<double>()
                << std::setprecision(1) << std::setw(10) << 1e3 * r["bnb_s"].get<double>()
                << std::setw(11) << r["bnb_scored"].get<std::int64_t>();
      if (r.contains("exhaustive_s"))
        std::cout << std::setw(12) << 1e3 * r["exhaustive_s"].get<double>() << std::setw(13)
                  << r["exhaustive_scored"].get<std::int64_t>() << std::setw(6)
                  << (r["same_score"].get<bool>() ? "yes" : "NO");
      std::cout << "\n";
    }
    std::cout << "\nmean per scan: branch and bound " << std::setprecision(1)
              << 1e3 * bnb_total / o->scans << " ms";
    if (o->exhaustive)
      std::cout << ", exhaustive " << 1e3 * ex_total / o->scans << " ms (x" << std::setprecision(0)
                << ex_total / bnb_total << ")";
    std::cout << "\n";
    result = 0;
  });
}

}  // namespace tessera::app
