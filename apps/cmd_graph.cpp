// `tessera graph optimize`: one g2o/TORO file through a solver (graph_optimize.hpp), printed as a
// line or as JSON.
#include "cli_inputs.hpp"
#include "commands.hpp"
#include "graph_optimize.hpp"

#include <tessera/runtime/options.hpp>

#include <iomanip>
#include <iostream>
#include <memory>

namespace tessera::app {

namespace pg = tessera::pose_graph;

void addGraphCommand(CLI::App& app, int& result) {
  auto* graph = app.add_subcommand("graph", "pose-graph tools (g2o / TORO files)");
  graph->require_subcommand(1);
  auto* cmd = graph->add_subcommand("optimize",
                                    "optimise a pose graph (SE(2) or SE(3)) and print what it did");
  auto o = std::make_shared<OptimizeOptions>();
  cmd->add_option("input", o->input, "g2o or TORO file")->required();
  cmd->add_option("--solver", o->solver, detail::enumChoices(pg::Solver{}))->capture_default_str();
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
    nlohmann::json j = optimizeFile(file, *o, options);
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

}  // namespace tessera::app
