// `tessera bench landmarks`: the point-landmark SLAM filters (docs/algorithms.md#landmark-slam).
//  1. Accuracy: the sim_landmarks profile (seed 004 world) for each filter over several
//     simulator seeds, in-process; per filter the mean ± std of ATE, landmark error, mean NIS and
//     the odometry ATE of the same runs.
//  2. Cost: time of one scan update (known ids, `--observations` sightings of mapped landmarks)
//     as the map grows, each filter, and the scaling exponent b of a least-squares fit
//     t = a n^b over the landmark counts. Synthetic: landmarks uniform in a 25 m disc around the
//     robot, all mapped before timing, the robot turning on the spot between scans.
#include "bench_commands.hpp"
#include "cli_inputs.hpp"

#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/landmark_slam/landmark_filter.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/profile.hpp>

#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <numbers>
#include <random>

namespace tessera::app {
namespace {

namespace fs = std::filesystem;
using landmark_slam::EkfSlam;
using landmark_slam::LandmarkFilter;
using landmark_slam::Observation;
using landmark_slam::RbUkfSlam;

struct Options {
  int seeds = 20;
  std::vector<int> landmarks{27, 50, 100, 200, 500, 1000, 2000};
  int observations = 10;
  int repeats = 20;
  std::vector<std::string> filters{"ekf", "rbekf"};
  std::string out = "out/bench_landmarks";
  bool json = false;
};

struct MeanStd {
  double mean = 0, std = 0;
};
MeanStd meanStd(const std::vector<double>& v) {
  MeanStd r;
  if (v.empty()) return r;
  for (double x : v) r.mean += x;
  r.mean /= static_cast<double>(v.size());
  if (v.size() > 1) {
    for (double x : v) r.std += (x - r.mean) * (x - r.mean);
    r.std = std::sqrt(r.std / static_cast<double>(v.size() - 1));
  }
  return r;
}

double summaryDouble(const Summary& s, const std::string& key) {
  const auto it = s.find(key);
  if (it == s.end() || !std::holds_alternative<double>(it->second))
    throw std::runtime_error("bench landmarks: the run reported no " + key);
  return std::get<double>(it->second);
}

nlohmann::json accuracy(const Options& o, const std::string& filter) {
  const std::string path = resolveProfilePath("sim_landmarks", profileSearchDirs());
  std::vector<double> ate, lm, nis, odom, us;
  for (int seed = 1; seed <= o.seeds; ++seed) {
    const fs::path dir = fs::path(o.out) / (filter + "_seed" + std::to_string(seed));
    fs::create_directories(dir);
    auto profile = loadProfile(path, {"filter=" + filter, "seed=" + std::to_string(seed)});
    RuntimeOptions ro;
    ro.show_progress = false;
    ro.output_dir = dir.string();
    ro.threads = 1;
    const RunReport report = buildRuntime(profile, ro)->run();
    for (const auto& a : report.actors) {
      if (a.name != "slam") continue;
      ate.push_back(summaryDouble(a.summary, "ate_rmse_m"));
      lm.push_back(summaryDouble(a.summary, "landmark_rmse_m"));
      nis.push_back(summaryDouble(a.summary, "mean_nis"));
      us.push_back(summaryDouble(a.summary, "update_us_mean"));
    }
    odom.push_back(
        tessera::evaluation::computeAte(tessera::mapping::readTum(dir / "odometry.tum"),
                                        tessera::mapping::readTum(dir / "ground_truth.tum"))
            .translation.rmse);
    if (!o.json) std::cerr << "[bench landmarks] " << filter << " seed " << seed << "\n";
  }
  const auto j = [](const MeanStd& m) { return nlohmann::json{{"mean", m.mean}, {"std", m.std}}; };
  return {{"filter", filter},
          {"seeds", o.seeds},
          {"ate_rmse_m", j(meanStd(ate))},
          {"landmark_rmse_m", j(meanStd(lm))},
          {"mean_nis", j(meanStd(nis))},
          {"odometry_ate_rmse_m", j(meanStd(odom))},
          {"update_us", j(meanStd(us))},
          {"ate_per_seed", ate}};
}

std::unique_ptr<LandmarkFilter> makeFilter(const std::string& name, std::size_t landmarks) {
  landmark_slam::LandmarkSlamOptions o;
  o.initial_std = {0.01, 0.01, 0.001};
  if (name == "ekf") {
    auto f = std::make_unique<EkfSlam>(o);
    f->reserveLandmarks(landmarks);
    return f;
  }
  return std::make_unique<RbUkfSlam>(o);
}

// Microseconds per scan update with n mapped landmarks.
double costPerUpdate(const Options& o, const std::string& filter, int n) {
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> radius(2.0, 25.0),
      angle(-std::numbers::pi, std::numbers::pi);
  std::vector<Eigen::Vector2d> world;
  for (int i = 0; i < n; ++i) {
    const double r = radius(rng), a = angle(rng);
    world.emplace_back(r * std::cos(a), r * std::sin(a));
  }
  auto f = makeFilter(filter, static_cast<std::size_t>(n));
  const auto sight = [&](int id) {
    const Eigen::Vector3d p = f->pose();
    const Eigen::Vector2d d = world[static_cast<std::size_t>(id)] - p.head<2>();
    return Observation{id, d.norm(), std::atan2(d.y(), d.x()) - p[2]};
  };
  std::vector<Observation> all;
  for (int i = 0; i < n; ++i) all.push_back(sight(i));
  f->update(all);
  std::uniform_int_distribution<int> pick(0, n - 1);
  tessera::landmark_slam::DriveInput turn;
  turn.turn_rate = 0.1;
  turn.dt = 0.1;
  double total = 0;
  for (int k = 0; k < o.repeats; ++k) {
    f->predict(turn);
    std::vector<Observation> scan;
    for (int j = 0; j < o.observations; ++j) scan.push_back(sight(pick(rng)));
    const auto t0 = std::chrono::steady_clock::now();
    f->update(scan);
    total += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  return 1e6 * total / o.repeats;
}

// Least-squares slope of log t against log n.
double exponent(const std::vector<int>& n, const std::vector<double>& t) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const double m = static_cast<double>(n.size());
  for (std::size_t i = 0; i < n.size(); ++i) {
    const double x = std::log(n[i]), y = std::log(t[i]);
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
  }
  return (m * sxy - sx * sy) / (m * sxx - sx * sx);
}

}  // namespace

void addBenchLandmarksCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "landmarks",
      "landmark SLAM: sim_landmarks accuracy over seeds, and cost per update vs map size with "
      "the fitted scaling exponent, for EKF-SLAM and the Rao-Blackwellised filter");
  auto o = std::make_shared<Options>();
  cmd->add_option("--seeds", o->seeds, "simulator seeds 1..N per filter (0 = skip accuracy)")
      ->capture_default_str();
  cmd->add_option("--landmarks", o->landmarks, "map sizes for the cost benchmark")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--observations", o->observations, "sightings per timed scan update")
      ->capture_default_str();
  cmd->add_option("--repeats", o->repeats, "timed scan updates per map size")
      ->capture_default_str();
  cmd->add_option("--filters", o->filters, "filters: ekf, rbekf")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--out", o->out, "output folder of the accuracy runs")->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    if (o->seeds < 0) throw ConfigError("--seeds must be >= 0");
    if (o->observations < 1 || o->repeats < 1)
      throw ConfigError("--observations and --repeats must be >= 1");
    for (int n : o->landmarks)
      if (n < 1) throw ConfigError("--landmarks: counts must be >= 1");
    for (const auto& f : o->filters)
      if (f != "ekf" && f != "rbekf")
        throw ConfigError("--filters: 'ekf' or 'rbekf', got '" + f + "'");

    nlohmann::json acc = nlohmann::json::array(), cost = nlohmann::json::array();
    if (o->seeds > 0)
      for (const auto& f : o->filters) acc.push_back(accuracy(*o, f));
    for (const auto& f : o->filters) {
      if (o->landmarks.empty()) break;
      std::vector<double> us;
      for (int n : o->landmarks) {
        if (!o->json) std::cerr << "[bench landmarks] " << f << " " << n << " landmarks\n";
        us.push_back(costPerUpdate(*o, f, n));
      }
      cost.push_back({{"filter", f},
                      {"landmarks", o->landmarks},
                      {"update_us", us},
                      {"exponent", o->landmarks.size() > 1 ? exponent(o->landmarks, us) : 0.0}});
    }
    if (o->json) {
      std::cout << nlohmann::json{{"machine", machineDescription()},
                                  {"observations_per_update", o->observations},
                                  {"accuracy", acc},
                                  {"cost", cost}}
                       .dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n";
    std::cout << std::fixed;
    if (!acc.empty()) {
      std::cout << "\nsim_landmarks (seed 004 world), seeds 1.." << o->seeds
                << ", mean ± std over seeds\n"
                << std::left << std::setw(8) << "filter" << std::right << std::setw(20)
                << "ATE rmse m" << std::setw(20) << "landmark rmse m" << std::setw(16) << "mean NIS"
                << std::setw(20) << "odometry ATE m" << std::setw(14) << "update us\n";
      for (const auto& a : acc) {
        const auto ms = [](const nlohmann::json& j, int p) {
          std::ostringstream s;
          s << std::fixed << std::setprecision(p) << j["mean"].get<double>() << " ± "
            << j["std"].get<double>();
          return s.str();
        };
        std::cout << std::left << std::setw(8) << a["filter"].get<std::string>() << std::right
                  << std::setw(20) << ms(a["ate_rmse_m"], 3) << std::setw(20)
                  << ms(a["landmark_rmse_m"], 3) << std::setw(16) << ms(a["mean_nis"], 2)
                  << std::setw(20) << ms(a["odometry_ate_rmse_m"], 2) << std::setw(13)
                  << std::setprecision(1) << a["update_us"]["mean"].get<double>() << "\n";
      }
    }
    if (!cost.empty()) {
      std::cout << "\ncost of one scan update (" << o->observations
                << " known-id sightings), microseconds\n"
                << std::setw(10) << "landmarks";
      for (const auto& c : cost) std::cout << std::setw(14) << c["filter"].get<std::string>();
      std::cout << "\n";
      for (std::size_t i = 0; i < o->landmarks.size(); ++i) {
        std::cout << std::setw(10) << o->landmarks[i];
        for (const auto& c : cost)
          std::cout << std::setw(14) << std::setprecision(1) << c["update_us"][i].get<double>();
        std::cout << "\n";
      }
      std::cout << std::setw(10) << "exponent";
      for (const auto& c : cost)
        std::cout << std::setw(14) << std::setprecision(2) << c["exponent"].get<double>();
      std::cout << "\n";
    }
    result = 0;
  });
}

}  // namespace tessera::app
