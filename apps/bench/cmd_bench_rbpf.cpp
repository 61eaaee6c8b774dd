// `tessera bench rbpf`: the local laser SLAM on a CARMEN log at several particle counts. Each
// count runs as its own `tessera run` child process (so peak RSS and CPU time are that run's
// alone), then its online trajectory is scored with the relations metric.
#include "bench_commands.hpp"
#include "cli_inputs.hpp"

#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>

#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>

namespace tessera::app {
namespace {

namespace fs = std::filesystem;

struct Options {
  std::string profile = "carmen_rbpf";
  std::string log = "../shared/data/intel-lab-mrpt/intel.clf.gz";
  std::string scan_times = "../shared/data/intel-lab-mrpt/frame_times.txt";
  std::string relations = "../shared/data/intel-lab-mrpt/intel.relations";
  std::vector<int> particles{10, 30};
  std::vector<std::string> sets;
  std::string out = "out/bench_rbpf";
  bool json = false;
};

/// Runs `tessera run` in a child process; stdout/stderr go to log_path. Returns its exit code.
int runChild(const std::vector<std::string>& args, const fs::path& log_path) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("bench rbpf: fork failed");
  if (pid == 0) {
    std::FILE* log = std::fopen(log_path.c_str(), "w");
    if (log) {
      ::dup2(::fileno(log), 1);
      ::dup2(::fileno(log), 2);
    }
    ::execv("/proc/self/exe", argv.data());
    std::_Exit(127);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

}  // namespace

void addBenchRbpfCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "rbpf",
      "RBPF laser SLAM on a CARMEN log: CPU, wall, peak RSS and relations error per "
      "particle count (each run in its own process)");
  auto o = std::make_shared<Options>();
  cmd->add_option("--profile", o->profile, "profile to run")->capture_default_str();
  cmd->add_option("--log", o->log, "CARMEN log")->capture_default_str();
  cmd->add_option("--scan-times", o->scan_times,
                  "per-scan times for the player (\"\" = the log's stamps)")
      ->capture_default_str();
  cmd->add_option("--relations", o->relations, "ground-truth relations")->capture_default_str();
  cmd->add_option("--particles", o->particles, "particle counts, e.g. 10,30,50")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--set", o->sets, "extra KEY=VALUE profile overrides for every run");
  cmd->add_option("--out", o->out, "output folder (one sub-folder per run)")->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    requireFile(o->log, "--log");
    if (!o->scan_times.empty()) requireFile(o->scan_times, "--scan-times");
    for (int n : o->particles)
      if (n < 1) throw ConfigError("--particles: counts must be >= 1, got " + std::to_string(n));
    const auto relations = loadPoseRelations(o->relations, "--relations");

    nlohmann::json runs = nlohmann::json::array();
    for (int n : o->particles) {
      const fs::path dir = fs::path(o->out) / ("particles_" + std::to_string(n));
      fs::create_directories(dir);
      std::vector<std::string> args{"tessera",
                                    "run",
                                    o->profile,
                                    "--out",
                                    dir.string(),
                                    "--set",
                                    "player.path=" + o->log,
                                    "--set",
                                    "rbpf.particles=" + std::to_string(n)};
      if (!o->scan_times.empty()) {
        args.push_back("--set");
        args.push_back("player.scan_times=" + o->scan_times);
      }
      for (const auto& s : o->sets) {
        args.push_back("--set");
        args.push_back(s);
      }
      if (!o->json) std::cerr << "[bench rbpf] " << n << " particles ...\n";
      const int code = runChild(args, dir / "run.log");
      if (code != 0)
        throw std::runtime_error("bench rbpf: the run with " + std::to_string(n) +
                                 " particles failed (exit " + std::to_string(code) + "), see " +
                                 (dir / "run.log").string());
      nlohmann::json summary;
      std::ifstream(dir / "summary.json") >> summary;
      const auto r = tessera::evaluation::computeRelationsError(
          tessera::mapping::readTum(dir / "trajectory.tum"), relations);
      runs.push_back({{"particles", n},
                      {"scans_read", summary.value("scans_read", 0)},
                      {"scans_processed", summary.value("scans_processed", 0)},
                      {"cpu_s", summary.value("cpu_s", 0.0)},
                      {"wall_s", summary.value("wall_s", 0.0)},
                      {"peak_rss_mb", summary.value("peak_rss_mb", 0.0)},
                      {"realtime_factor", summary.value("realtime_factor", 0.0)},
                      {"relations_matched", r.matched},
                      {"trans_mean_m", r.translation.mean},
                      {"trans_std_m", r.translation.std},
                      {"rot_mean_deg", r.rotation_deg.mean},
                      {"rot_std_deg", r.rotation_deg.std},
                      {"out", dir.string()}});
    }
    if (o->json) {
      std::cout << nlohmann::json{{"machine", machineDescription()},
                                  {"profile", o->profile},
                                  {"log", o->log},
                                  {"runs", runs}}
                       .dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << "profile " << o->profile << " on " << o->log << "\n"
              << "relations error of the online trajectory (" << o->relations << ")\n\n"
              << std::right << std::setw(9) << "particles" << std::setw(8) << "updates"
              << std::setw(9) << "CPU s" << std::setw(9) << "wall s" << std::setw(10) << "RSS MB"
              << std::setw(22) << "trans m (mean±std)" << std::setw(10) << "rot deg" << std::setw(9)
              << "matched\n";
    std::cout << std::fixed;
    for (const auto& r : runs) {
      std::ostringstream trans;
      trans << std::fixed << std::setprecision(3) << r["trans_mean_m"].get<double>() << " ± "
            << r["trans_std_m"].get<double>();
      std::cout << std::setw(9) << r["particles"].get<int>() << std::setw(8)
                << r["scans_processed"].get<std::int64_t>() << std::setprecision(1) << std::setw(9)
                << r["cpu_s"].get<double>() << std::setw(9) << r["wall_s"].get<double>()
                << std::setw(10) << r["peak_rss_mb"].get<double>() << std::setw(22) << trans.str()
                << std::setprecision(2) << std::setw(10) << r["rot_mean_deg"].get<double>()
                << std::setw(9) << r["relations_matched"].get<std::size_t>() << "\n";
    }
    result = 0;
  });
}

}  // namespace tessera::app
