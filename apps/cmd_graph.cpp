// `tessera graph optimize` (one g2o/TORO file through a solver) and `tessera bench graph` (the
// shared pose graphs through every solver, from the file's poses and from odometry chaining,
// beside g2o's figures, docs/benchmarks.md#pose-graphs-tessera-bench-graph, in one run so the
// ratios are honest).
#include "cli_inputs.hpp"
#include "commands.hpp"

#include <tessera/pose_graph/optimizer.hpp>
#include <tessera/pose_graph/pose_graph_io.hpp>
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

nlohmann::json summaryJson(const pg::OptimizerSummary& s, int nodes, std::size_t edges) {
  return {{"nodes", nodes},
          {"edges", edges},
          {"initial_chi2", s.initial_chi2},
          {"final_chi2", s.final_chi2},
          {"iterations", s.iterations},
          {"sgd_iterations", s.sgd_iterations},
          {"ceres_iterations", s.ceres_iterations},
          {"seconds", s.seconds},
          {"solver", pg::solverName(s.solver)},
          {"converged", s.converged},
          {"message", s.message}};
}

/// Takes the start poses from another file's vertices (e.g. an earlier solution); every node of
/// the graph must be there.
template <class G>
void startFrom(G& graph, const G& other, const std::string& path) {
  for (int i = 0; i < graph.size(); ++i) {
    if (!other.contains(graph.ids[i]))
      throw ConfigError("--init-poses: " + path + " has no vertex " + std::to_string(graph.ids[i]));
    graph.poses[i] = other.poses[other.index(graph.ids[i])];
  }
}

void startFrom(pg::Graph2D& graph, const std::string& path) {
  startFrom(graph, pg::readPoseGraph2D(path), path);
}

void startFrom(pg::Graph3D& graph, const std::string& path) {
  startFrom(graph, pg::readPoseGraph3D(path), path);
}

struct OptimizeOptions {
  std::string input;
  std::string solver = "sgd+ceres";
  std::string init = "file";
  std::string out;
  std::string init_poses;  // a g2o/TORO file whose vertices give the start (same ids)
  int sgd_iterations = pg::SgdOptions{}.iterations;
  int ceres_iterations = pg::CeresOptions{}.max_iterations;
  double huber = 0.0;
  std::string method = "lm";
  bool json = false;
};

pg::OptimizerOptions solverOptions(const OptimizeOptions& o) {
  pg::OptimizerOptions options;
  options.solver = pg::parseSolver(o.solver);
  options.sgd.iterations = o.sgd_iterations;
  options.ceres.max_iterations = o.ceres_iterations;
  options.ceres.huber_delta = o.huber;
  options.ceres.method = pg::parseMethod(o.method);
  return options;
}

/// Reads, optionally re-initialises, optimises and (if asked) writes one graph.
template <class Graph>
nlohmann::json optimizeFile(Graph graph, const OptimizeOptions& o,
                            const pg::OptimizerOptions& options) {
  // Edges between consecutive nodes are odometry; the others are loop closures, which get the
  // robust loss when one is asked for.
  for (auto& e : graph.edges) e.robust = std::abs(e.from - e.to) != 1;
  if (o.init == "odometry") pg::initializeFromOdometry(graph);
  if (!o.init_poses.empty()) startFrom(graph, o.init_poses);
  const auto summary = pg::optimize(graph, options);
  if (!o.out.empty()) {
    pg::writeG2o(graph, o.out);
  }
  return summaryJson(summary, graph.size(), graph.edges.size());
}

// --- bench -----------------------------------------------------------------------------------

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

void addGraphCommand(CLI::App& app, int& result) {
  auto* graph = app.add_subcommand("graph", "pose-graph tools (g2o / TORO files)");
  graph->require_subcommand(1);
  auto* cmd = graph->add_subcommand("optimize",
                                    "optimise a pose graph (SE(2) or SE(3)) and print what it did");
  auto o = std::make_shared<OptimizeOptions>();
  cmd->add_option("input", o->input, "g2o or TORO file")->required();
  cmd->add_option("--solver", o->solver, "sgd | ceres | sgd+ceres")->capture_default_str();
  cmd->add_option("--init", o->init,
                  "file: start from the file's poses; odometry: chain the odometry edges")
      ->capture_default_str();
  cmd->add_option("--out", o->out, "write the optimised graph here (g2o)");
  cmd->add_option("--init-poses", o->init_poses,
                  "start from the vertices of this g2o/TORO file instead (same ids; e.g. an "
                  "earlier solution)");
  cmd->add_option("--sgd-iterations", o->sgd_iterations, "SGD passes")->capture_default_str();
  cmd->add_option("--iterations", o->ceres_iterations, "Ceres iterations (max)")
      ->capture_default_str();
  cmd->add_option("--method", o->method,
                  "Ceres stage: lm (Levenberg-Marquardt), dogleg, or gn (undamped Gauss-Newton, "
                  "as g2o)")
      ->capture_default_str();
  cmd->add_option("--huber", o->huber,
                  "Huber scale on loop-closure edges (0 = off: the plain g2o objective)")
      ->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    requireFile(o->input, "input");
    if (!o->init_poses.empty()) requireFile(o->init_poses, "--init-poses");
    if (o->init != "file" && o->init != "odometry")
      throw ConfigError("--init: expected file or odometry, got '" + o->init + "'");
    if (o->sgd_iterations < 0 || o->ceres_iterations < 0)
      throw ConfigError("--sgd-iterations/--iterations must be >= 0");
    if (o->huber < 0) throw ConfigError("--huber must be >= 0");
    pg::OptimizerOptions options;
    try {
      options = solverOptions(*o);
    } catch (const std::invalid_argument& e) {
      throw ConfigError(std::string("--solver/--method: ") + e.what());
    }
    const auto file = pg::readPoseGraph(o->input);
    nlohmann::json j = file.dimension == 2 ? optimizeFile(file.graph2d, *o, options)
                                           : optimizeFile(file.graph3d, *o, options);
    j["dimension"] = file.dimension;
    j["input"] = o->input;
    j["init"] = o->init;
    if (o->json) {
      std::cout << j.dump(2) << "\n";
    } else {
      std::cout << o->input << ": " << j["nodes"] << " nodes, " << j["edges"] << " edges ("
                << file.dimension << "D), init " << o->init << "\n"
                << std::setprecision(10) << "solver " << o->solver << ": chi2 "
                << j["initial_chi2"].get<double>() << " -> " << j["final_chi2"].get<double>()
                << " in " << j["iterations"] << " iterations, " << std::setprecision(3)
                << j["seconds"].get<double>() << " s\n"
                << j["message"].get<std::string>() << "\n";
      if (!o->out.empty()) std::cout << "wrote " << o->out << "\n";
    }
    result = 0;
  });
}

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
          nlohmann::json j = file.dimension == 2
                                 ? optimizeFile(file.graph2d, opt, solverOptions(opt))
                                 : optimizeFile(file.graph3d, opt, solverOptions(opt));
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
