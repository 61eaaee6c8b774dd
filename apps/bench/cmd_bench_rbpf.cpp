// `tessera bench rbpf`: laser SLAM profiles on a CARMEN log (by default the RBPF alone,
// carmen_rbpf, against the two-level pipeline, carmen_global) over particle counts and seeds.
// Each run is its own `tessera run` child process (so peak RSS and CPU time are that run's
// alone); its online (trajectory.tum) and final (trajectory_final.tum) trajectories are scored
// with the relations metric. Runs are interleaved across profiles so that machine noise falls
// on all of them alike.
#include "bench_commands.hpp"
#include "bench_util.hpp"
#include "child_process.hpp"
#include "cli_inputs.hpp"

#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>

namespace tessera::app {
namespace {

namespace fs = std::filesystem;

struct Options {
  std::vector<std::string> profiles{"carmen_rbpf", "carmen_global"};
  std::string log = "../shared/data/intel-lab-mrpt/intel.clf.gz";
  std::string scan_times = "../shared/data/intel-lab-mrpt/frame_times.txt";
  std::string relations = "../shared/data/intel-lab-mrpt/intel.relations";
  std::vector<int> particles{10};
  std::vector<int> seeds{1, 2, 3};
  int rounds = 1;
  std::vector<std::string> sets;
  std::string out = "out/bench_rbpf";
  bool json = false;
};

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0 : s / static_cast<double>(v.size());
}

/// Relations error of one trajectory file; matched = 0 when the file is missing or empty.
nlohmann::json scoreTrajectory(const fs::path& file,
                               const std::vector<tessera::evaluation::PoseRelation>& relations) {
  if (!fs::exists(file)) return {{"matched", 0}};
  const auto r =
      tessera::evaluation::computeRelationsError(tessera::mapping::readTum(file), relations);
  return {{"matched", r.matched},
          {"trans_mean_m", r.translation.mean},
          {"trans_std_m", r.translation.std},
          {"rot_mean_deg", r.rotation_deg.mean},
          {"rot_std_deg", r.rotation_deg.std}};
}

}  // namespace

void addBenchRbpfCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "rbpf",
      "RBPF laser SLAM on a CARMEN log: CPU, wall, peak RSS and relations error per "
      "particle count (each run in its own process)");
  auto o = std::make_shared<Options>();
  cmd->add_option("--profiles,--profile", o->profiles,
                  "profiles to run, e.g. carmen_rbpf,carmen_global")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--log", o->log, "CARMEN log")->capture_default_str();
  cmd->add_option("--scan-times", o->scan_times,
                  "per-scan times for the player (\"\" = the log's stamps)")
      ->capture_default_str();
  cmd->add_option("--relations", o->relations, "ground-truth relations")->capture_default_str();
  cmd->add_option("--particles", o->particles, "particle counts, e.g. 10,30,50")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--seeds", o->seeds, "filter seeds (slam.rbpf.seed); accuracy is their mean")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--rounds", o->rounds, "runs of every (profile, particles, seed), interleaved")
      ->capture_default_str();
  cmd->add_option("--set", o->sets, "extra KEY=VALUE profile overrides for every run");
  cmd->add_option("--out", o->out, "output folder (one sub-folder per run)")->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    requireFile(o->log, "--log");
    if (!o->scan_times.empty()) requireFile(o->scan_times, "--scan-times");
    for (int n : o->particles)
      if (n < 1) throw ConfigError("--particles: counts must be >= 1, got " + std::to_string(n));
    if (o->rounds < 1) throw ConfigError("--rounds must be >= 1, got " + std::to_string(o->rounds));
    if (o->profiles.empty() || o->seeds.empty())
      throw ConfigError("--profiles and --seeds need at least one value");
    const auto relations = loadPoseRelations(o->relations, "--relations");

    // Rounds and seeds outermost, profiles innermost: the profiles compared see the machine in
    // the same state, one run after the other.
    nlohmann::json runs = nlohmann::json::array();
    const std::size_t total = static_cast<std::size_t>(o->rounds) * o->seeds.size() *
                              o->particles.size() * o->profiles.size();
    std::size_t done = 0;
    for (int round = 1; round <= o->rounds; ++round)
      for (int seed : o->seeds)
        for (int n : o->particles)
          for (const auto& profile : o->profiles) {
            const std::string name = profile + "_p" + std::to_string(n) + "_s" +
                                     std::to_string(seed) + "_r" + std::to_string(round);
            const fs::path dir = fs::path(o->out) / name;
            fs::create_directories(dir);
            std::vector<std::string> args{"tessera", "run",
                                          profile,   "--quiet",
                                          "--out",   dir.string(),
                                          "--set",   "player.path=" + o->log,
                                          "--set",   "slam.rbpf.particles=" + std::to_string(n),
                                          "--set",   "slam.rbpf.seed=" + std::to_string(seed)};
            if (!o->scan_times.empty()) {
              args.push_back("--set");
              args.push_back("player.scan_times=" + o->scan_times);
            }
            for (const auto& s : o->sets) {
              args.push_back("--set");
              args.push_back(s);
            }
            ++done;
            if (!o->json)
              std::cerr << "[bench rbpf] " << done << "/" << total << " " << name << " ...\n";
            const int code = runTesseraChild(args, dir / "run.log");
            if (code != 0)
              throw std::runtime_error("bench rbpf: run " + name + " failed (exit " +
                                       std::to_string(code) + "), see " +
                                       (dir / "run.log").string());
            nlohmann::json summary;
            std::ifstream(dir / "summary.json") >> summary;
            nlohmann::json memory = nlohmann::json::object();
            // A named copy: items() of a temporary would outlive it.
            const nlohmann::json actors = summary.value("actors", nlohmann::json::object());
            for (const auto& [actor, figures] : actors.items())
              if (figures.contains("memory_peak_mb")) memory[actor] = figures["memory_peak_mb"];
            runs.push_back({{"profile", profile},
                            {"particles", n},
                            {"seed", seed},
                            {"round", round},
                            {"scans_read", summary.value("scans_read", 0)},
                            {"scans_processed", summary.value("scans_processed", 0)},
                            {"cpu_s", summary.value("cpu_s", 0.0)},
                            {"wall_s", summary.value("wall_s", 0.0)},
                            {"peak_rss_mb", summary.value("peak_rss_mb", 0.0)},
                            {"actor_memory_peak_mb", memory},
                            {"live_correction_max_m", summary.value("live_correction_max_m", 0.0)},
                            {"online", scoreTrajectory(dir / "trajectory.tum", relations)},
                            {"final", scoreTrajectory(dir / "trajectory_final.tum", relations)},
                            {"out", dir.string()}});
          }

    // Per profile and particle count: accuracy is the mean over seeds (each seed's runs agree
    // but for thread timing), CPU and memory the median over every run.
    nlohmann::json profiles = nlohmann::json::array();
    for (const auto& profile : o->profiles)
      for (int n : o->particles) {
        std::vector<double> cpu, rss, jump;
        std::map<std::string, std::vector<double>> acc;
        for (const auto& r : runs) {
          if (r["profile"] != profile || r["particles"] != n) continue;
          cpu.push_back(r["cpu_s"].get<double>());
          rss.push_back(r["peak_rss_mb"].get<double>());
          jump.push_back(r["live_correction_max_m"].get<double>());
          for (const char* which : {"online", "final"}) {
            const auto& t = r[which];
            if (t.value("matched", 0) == 0) continue;
            acc[std::string(which) + "_trans_m"].push_back(t["trans_mean_m"].get<double>());
            acc[std::string(which) + "_rot_deg"].push_back(t["rot_mean_deg"].get<double>());
          }
        }
        nlohmann::json row{{"profile", profile},
                           {"particles", n},
                           {"runs", cpu.size()},
                           {"cpu_s_median", median(cpu)},
                           {"peak_rss_mb_median", median(rss)},
                           {"live_correction_max_m",
                            jump.empty() ? 0.0 : *std::max_element(jump.begin(), jump.end())}};
        for (const char* key :
             {"online_trans_m", "online_rot_deg", "final_trans_m", "final_rot_deg"})
          row[key] = acc.count(key) ? nlohmann::json(mean(acc[key])) : nlohmann::json(nullptr);
        profiles.push_back(row);
      }

    if (o->json) {
      std::cout << nlohmann::json{{"machine", machineDescription()},
                                  {"log", o->log},
                                  {"relations", o->relations},
                                  {"profiles", profiles},
                                  {"runs", runs}}
                       .dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << "log " << o->log << ", relations " << o->relations << "\n"
              << "relations error: online = trajectory.tum (the live pose), final = "
                 "trajectory_final.tum; mean over seeds; CPU and RSS: median of runs\n\n";
    const auto cell = [](const nlohmann::json& v, int precision) {
      if (v.is_null()) return std::string("-");
      std::ostringstream s;
      s << std::fixed << std::setprecision(precision) << v.get<double>();
      return s.str();
    };
    std::cout << std::left << std::setw(16) << "profile" << std::right << std::setw(10)
              << "particles" << std::setw(6) << "runs" << std::setw(8) << "CPU s" << std::setw(9)
              << "RSS MB" << std::setw(18) << "online m / deg" << std::setw(18) << "final m / deg"
              << std::setw(12) << "max jump m\n";
    for (const auto& r : profiles) {
      std::cout << std::left << std::setw(16) << r["profile"].get<std::string>() << std::right
                << std::setw(10) << r["particles"].get<int>() << std::setw(6)
                << r["runs"].get<std::size_t>() << std::setw(8) << cell(r["cpu_s_median"], 1)
                << std::setw(9) << cell(r["peak_rss_mb_median"], 1) << std::setw(18)
                << (cell(r["online_trans_m"], 4) + " / " + cell(r["online_rot_deg"], 2))
                << std::setw(18)
                << (cell(r["final_trans_m"], 4) + " / " + cell(r["final_rot_deg"], 2))
                << std::setw(11) << cell(r["live_correction_max_m"], 3) << "\n";
    }
    result = 0;
  });
}

}  // namespace tessera::app
