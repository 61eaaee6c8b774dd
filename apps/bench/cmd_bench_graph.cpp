// `tessera bench graph`: the shared pose graphs through every solver, from the file's poses and
// from odometry chaining, beside g2o's figures
// (docs/benchmarks.md#pose-graphs-tessera-bench-graph), in one run so the ratios are honest.
#include "bench_commands.hpp"
#include "cli_inputs.hpp"
#include "graph_optimize.hpp"

#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>

namespace tessera::app {
namespace {

namespace fs = std::filesystem;
namespace pg = tessera::pose_graph;

struct BenchCase {
  std::string file;  // under the data root
  std::string init;  // file | odometry
  double g2o_chi2;   // g2o's figure (docs/benchmarks.md#pose-graphs-tessera-bench-graph)
                     // (Gauss-Newton, CHOLMOD, 20 iterations); 0 = none
  double g2o_seconds;
};

const std::vector<BenchCase>& benchCases() {
  static const std::vector<BenchCase> cases{
      {"posegraphs/M3500.g2o", "file", 137.912951, 0.26},
      {"posegraphs/manhattanOlson3500.g2o", "file", 146.076613, 0.30},
      {"posegraph-toro/input_INTEL_g2o.graph", "file", 215.830235, 0.05},
      {"posegraph-g2o/intel.g2o", "file", 45.004696, 0.24},
      {"posegraph-g2o/sphere2500.g2o", "file", 727.149472, 2.56},
      {"posegraphs/M3500.g2o", "odometry", 137.912951, 0.0},
      {"posegraphs/manhattanOlson3500.g2o", "odometry", 146.076613, 0.0},
      {"posegraph-g2o/manhattan.g2o", "odometry", 3549.04, 0.46},
  };
  return cases;
}

struct BenchOptions {
  std::string data = "../shared/data";
  std::vector<std::string> solvers{"ceres", "sgd+ceres"};
  std::vector<std::string> methods{"lm", "gn"};
  int sgd_iterations = pg::SgdOptions{}.iterations;
  bool json = false;
};

}  // namespace

void addBenchGraphCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "graph",
      "pose-graph solvers on the shared g2o/TORO graphs: final chi2 and time beside g2o's");
  auto o = std::make_shared<BenchOptions>();
  cmd->add_option("--data", o->data, "dataset root")->capture_default_str();
  cmd->add_option("--solvers", o->solvers, "solvers to run")->delimiter(',')->capture_default_str();
  cmd->add_option("--methods", o->methods, "Ceres-stage methods to run (lm, dogleg, gn)")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--sgd-iterations", o->sgd_iterations, "SGD passes")->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    for (const auto& s : o->solvers) {
      try {
        pg::parseSolver(s);
      } catch (const std::invalid_argument& e) {
        throw ConfigError(std::string("--solvers: ") + e.what());
      }
    }
    for (const auto& m : o->methods) {
      try {
        pg::parseMethod(m);
      } catch (const std::invalid_argument& e) {
        throw ConfigError(std::string("--methods: ") + e.what());
      }
    }
    nlohmann::json runs = nlohmann::json::array();
    if (!o->json) std::cout << "machine: " << machineDescription() << "\n\n";
    for (const auto& c : benchCases()) {
      const fs::path path = fs::path(o->data) / c.file;
      requireFile(path.string(), "--data");
      const auto file = pg::readPoseGraph(path);
      for (const auto& solver : o->solvers)
        for (const auto& method : o->methods) {
          OptimizeOptions opt;
          opt.solver = solver;
          opt.method = method;
          opt.init = c.init;
          opt.sgd_iterations = o->sgd_iterations;
          if (!o->json)
            std::cerr << "[bench graph] " << c.file << " (" << c.init << ") " << solver << " ...\n";
          nlohmann::json j = optimizeFile(file, opt, solverOptions(opt));
          j["file"] = c.file;
          j["method"] = method;
          j["init"] = c.init;
          j["g2o_chi2"] = c.g2o_chi2;
          j["g2o_seconds"] = c.g2o_seconds;
          j["relative_to_g2o"] = (j["final_chi2"].get<double>() - c.g2o_chi2) / c.g2o_chi2;
          runs.push_back(j);
        }
    }
    if (o->json) {
      std::cout << nlohmann::json{{"machine", machineDescription()}, {"runs", runs}}.dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << std::left << std::setw(38) << "graph" << std::setw(9) << "init" << std::setw(14)
              << "solver" << std::right << std::setw(16) << "initial chi2" << std::setw(14)
              << "final chi2" << std::setw(14) << "g2o chi2" << std::setw(11) << "rel diff"
              << std::setw(7) << "iters" << std::setw(9) << "s" << std::setw(8) << "g2o s"
              << "\n";
    for (const auto& r : runs) {
      std::ostringstream rel;
      rel << std::scientific << std::setprecision(1) << r["relative_to_g2o"].get<double>();
      std::cout << std::left << std::setw(38) << r["file"].get<std::string>() << std::setw(9)
                << r["init"].get<std::string>() << std::setw(14)
                << (r["solver"].get<std::string>() + "/" + r["method"].get<std::string>())
                << std::right << std::fixed << std::setprecision(2) << std::setw(16)
                << r["initial_chi2"].get<double>() << std::setprecision(4) << std::setw(14)
                << r["final_chi2"].get<double>() << std::setw(14) << r["g2o_chi2"].get<double>()
                << std::setw(11) << rel.str() << std::setw(7) << r["iterations"].get<int>()
                << std::setprecision(3) << std::setw(9) << r["seconds"].get<double>()
                << std::setprecision(2) << std::setw(8) << r["g2o_seconds"].get<double>() << "\n";
    }
    std::cout
        << "\ng2o: Gauss-Newton, CHOLMOD, 20 iterations, as measured in docs/benchmarks.md (loaded "
           "machine; manhattan.g2o from odometry: g2o stuck at 3549.04).\n";
    result = 0;
  });
}

}  // namespace tessera::app
