// tessera bench batch: the scaling curve of batch reprocessing (tessera batch) against worker
// processes, beside the same profile run in one process. Rounds outermost and configurations
// interleaved inside each, so machine noise falls on all of them alike; medians are reported.
// Every run is a child process; its wall time is measured here, the map and reduce split is read
// from its batch.json, and the keyframe ATE from its keyframes.tum against ground_truth.tum.
#include "bench_commands.hpp"
#include "bench_util.hpp"
#include "child_process.hpp"

#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/process_stats.hpp>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>

namespace tessera::app {

namespace {

namespace fs = std::filesystem;

struct Options {
  std::string profile = "rgbd_slam";
  std::string dataset = "../shared/data/7scenes-redkitchen-rgbd";
  std::vector<int> workers{1, 2, 4};
  int shards = 4;
  int rounds = 3;
  std::vector<std::string> sets;
  std::string out = "out/bench_batch";
  bool json = false;
};

double keyframeAte(const fs::path& dir) {
  const auto est = dir / "keyframes.tum", ref = dir / "ground_truth.tum";
  if (!fs::exists(est) || !fs::exists(ref)) return -1;
  evaluation::AteOptions o;
  o.dimension = evaluation::Dimension::kSpatial;
  return evaluation::computeAte(mapping::readTum(est), mapping::readTum(ref), o).translation.rmse;
}

struct Sample {
  double wall_s = 0, map_s = 0, reduce_s = 0, ate_m = 0;
};

/// One run as a child process; throws with its log's path when it fails.
Sample runOne(const std::vector<std::string>& args, const fs::path& dir) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  const auto t0 = std::chrono::steady_clock::now();
  const int code = runTesseraChild(args, dir / "run.log");
  Sample s;
  s.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (code != 0)
    throw std::runtime_error("bench batch: run failed (exit " + std::to_string(code) + "): see " +
                             (dir / "run.log").string());
  if (std::ifstream in(dir / "batch.json"); in) {
    const auto j = nlohmann::json::parse(in);
    s.map_s = j.value("map_wall_s", 0.0);
    s.reduce_s = j.value("reduce_wall_s", 0.0);
  }
  s.ate_m = keyframeAte(dir);
  return s;
}

int run(const Options& o) {
  if (!fs::is_directory(o.dataset))
    throw std::runtime_error("bench batch: dataset folder " + o.dataset +
                             " not found (--dataset DIR: a TUM RGB-D or 7-Scenes folder)");
  std::vector<std::string> common = {"--set", "player.path=" + fs::absolute(o.dataset).string(),
                                     "--quiet"};
  for (const auto& s : o.sets) {
    common.push_back("--set");
    common.push_back(s);
  }
  std::vector<Sample> one;
  std::map<int, std::vector<Sample>> batch;
  for (int r = 0; r < o.rounds; ++r) {
    const fs::path ref_dir = fs::path(o.out) / ("one_process_" + std::to_string(r));
    std::vector<std::string> args = {"tessera", "run", o.profile, "--out", ref_dir.string()};
    args.insert(args.end(), common.begin(), common.end());
    one.push_back(runOne(args, ref_dir));
    std::cerr << "round " << r + 1 << "/" << o.rounds << ": one process " << std::fixed
              << std::setprecision(2) << one.back().wall_s << " s";
    for (const int w : o.workers) {
      const fs::path dir =
          fs::path(o.out) / ("workers_" + std::to_string(w) + "_" + std::to_string(r));
      std::vector<std::string> b = {"tessera",
                                    "batch",
                                    o.profile,
                                    "--workers",
                                    std::to_string(w),
                                    "--shards",
                                    std::to_string(o.shards),
                                    "--out",
                                    dir.string()};
      b.insert(b.end(), common.begin(), common.end());
      batch[w].push_back(runOne(b, dir));
      std::cerr << ", " << w << " worker(s) " << batch[w].back().wall_s << " s";
    }
    std::cerr << "\n";
  }
  const auto med = [](const std::vector<Sample>& v, double Sample::*field) {
    std::vector<double> x;
    for (const auto& s : v) x.push_back(s.*field);
    return median(x);
  };
  const double one_wall = med(one, &Sample::wall_s);
  const double base_wall = med(batch[o.workers.front()], &Sample::wall_s);
  const double base_map = med(batch[o.workers.front()], &Sample::map_s);
  nlohmann::json curve = nlohmann::json::array();
  for (const int w : o.workers) {
    const auto& v = batch[w];
    const double wall = med(v, &Sample::wall_s), map = med(v, &Sample::map_s);
    curve.push_back({{"workers", w},
                     {"wall_s", wall},
                     {"map_s", map},
                     {"reduce_s", med(v, &Sample::reduce_s)},
                     {"speedup", wall > 0 ? base_wall / wall : 0.0},
                     {"map_speedup", map > 0 ? base_map / map : 0.0},
                     {"speedup_over_one_process", wall > 0 ? one_wall / wall : 0.0},
                     {"keyframe_ate_m", med(v, &Sample::ate_m)}});
  }
  const nlohmann::json result = {
      {"machine", machineDescription()},
      {"profile", o.profile},
      {"dataset", o.dataset},
      {"shards", o.shards},
      {"rounds", o.rounds},
      {"one_process", {{"wall_s", one_wall}, {"keyframe_ate_m", med(one, &Sample::ate_m)}}},
      {"curve", curve}};
  if (o.json) {
    std::cout << result.dump(2) << "\n";
    return 0;
  }
  std::cout << "machine: " << machineDescription() << "\n"
            << o.profile << " on " << o.dataset << ", " << o.shards << " shards, medians of "
            << o.rounds << " rounds\n"
            << std::fixed << std::setprecision(2) << "one process: " << one_wall
            << " s wall, keyframe ATE " << std::setprecision(4) << med(one, &Sample::ate_m)
            << " m\n"
            << "workers   wall s   map s   reduce s   speedup   map speedup   keyframe ATE m\n";
  for (const auto& c : curve)
    std::cout << std::setw(7) << c["workers"].get<int>() << std::setprecision(2) << std::setw(9)
              << c["wall_s"].get<double>() << std::setw(8) << c["map_s"].get<double>()
              << std::setw(11) << c["reduce_s"].get<double>() << std::setw(10)
              << c["speedup"].get<double>() << std::setw(14) << c["map_speedup"].get<double>()
              << std::setprecision(4) << std::setw(17) << c["keyframe_ate_m"].get<double>() << "\n";
  return 0;
}

}  // namespace

void addBenchBatchCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "batch",
      "batch reprocessing (tessera batch): wall time, map/reduce split, speedup and keyframe ATE "
      "against worker processes, beside the profile in one process");
  auto o = std::make_shared<Options>();
  cmd->add_option("--profile", o->profile, "profile (rgbd_player + rgbd_front_end)");
  cmd->add_option("--dataset", o->dataset, "TUM RGB-D or 7-Scenes folder");
  cmd->add_option("--workers", o->workers, "worker counts, e.g. 1,2,4")
      ->delimiter(',')
      ->check(CLI::Range(1, 256));
  cmd->add_option("--shards", o->shards, "shards per batch (the same for every worker count)")
      ->check(CLI::Range(1, 4096));
  cmd->add_option("--rounds", o->rounds, "rounds (medians over them)")->check(CLI::Range(1, 100));
  cmd->add_option("--set", o->sets, "override passed to every run (ACTOR.KEY=VALUE)");
  cmd->add_option("--out", o->out, "folder for the runs' outputs");
  cmd->add_flag("--json", o->json, "print one JSON object");
  cmd->callback([o, &result] { result = run(*o); });
}

}  // namespace tessera::app
