// `tessera bench planner`: global planners on a 2000 × 2000 synthetic office costmap
// (nav_planning_bench.hpp): median and p95 wall time per plan, median CPU time of the planning
// thread (steadier when other processes share the cores), path length, cost, cells expanded.
#include "bench_commands.hpp"
#include "nav_planning_bench.hpp"

#include <tessera/runtime/process_stats.hpp>

#include <nlohmann/json.hpp>

#include <iomanip>
#include <iostream>
#include <memory>

namespace tessera::app {

void addBenchPlannerCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "planner",
      "global planners (Dijkstra, A*, A* + line of sight, + ant colony) on a synthetic office "
      "costmap: ms per plan, path length and cost, cells expanded");
  struct Options {
    PlanningBenchOptions bench;
    bool json = false;
  };
  auto o = std::make_shared<Options>();
  cmd->add_option("--cells", o->bench.cells, "map side [cells]")->capture_default_str();
  cmd->add_option("--resolution", o->bench.resolution, "[m/cell]")->capture_default_str();
  cmd->add_option("--seed", o->bench.seed, "office layout seed")->capture_default_str();
  cmd->add_option("--pairs", o->bench.pairs, "start/goal pairs")->capture_default_str();
  cmd->add_option("--distance", o->bench.pair_distance, "[m] start to goal, straight line")
      ->capture_default_str();
  cmd->add_option("--landmarks", o->bench.landmarks,
                  "landmark bounds for A* (astar_landmarks, and under LOS / ant colony); 0: none")
      ->capture_default_str();
  cmd->add_option("--repeat", o->bench.repeat, "timed runs per pair and planner")
      ->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    if (!o->json) std::cerr << "[bench planner] building the office costmap and planning ...\n";
    const PlanningBenchResult r = runPlanningBench(o->bench);
    nlohmann::json results = nlohmann::json::array();
    for (const auto& f : r.results)
      results.push_back({{"planner", f.planner},
                         {"ms_median", f.ms_median},
                         {"ms_p95", f.ms_p95},
                         {"cpu_ms_median", f.cpu_ms_median},
                         {"length_m", f.length_m},
                         {"cost", f.cost},
                         {"expanded", f.expanded},
                         {"solved", f.solved}});
    nlohmann::json pairs = nlohmann::json::array();
    for (const auto& p : r.pairs)
      pairs.push_back({{"start", {p.start.x(), p.start.y()}},
                       {"goal", {p.goal.x(), p.goal.y()}},
                       {"straight_m", p.straight_m}});
    if (o->json) {
      std::cout << nlohmann::json{{"machine", machineDescription()},
                                  {"map_cells", {r.width, r.height}},
                                  {"resolution_m", r.resolution},
                                  {"seed", o->bench.seed},
                                  {"repeat", o->bench.repeat},
                                  {"map_ms", r.map_ms},
                                  {"landmarks", o->bench.landmarks},
                                  {"landmarks_ms", r.landmarks_ms},
                                  {"pairs", pairs},
                                  {"results", results}}
                       .dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << "office costmap " << r.width << " x " << r.height << " cells at " << r.resolution
              << " m (seed " << o->bench.seed << ", built and inflated in " << std::fixed
              << std::setprecision(0) << r.map_ms << " ms; " << o->bench.landmarks
              << " landmarks in " << r.landmarks_ms << " ms); " << r.pairs.size()
              << " start/goal pairs " << std::setprecision(1) << o->bench.pair_distance
              << " m apart, " << o->bench.repeat << " timed runs each\n\n"
              << std::left << std::setw(16) << "planner" << std::right << std::setw(11)
              << "ms median" << std::setw(9) << "ms p95" << std::setw(11) << "cpu ms"
              << std::setw(11) << "length m" << std::setw(9) << "cost" << std::setw(11)
              << "expanded" << std::setw(8) << "solved\n";
    for (const auto& f : r.results)
      std::cout << std::left << std::setw(16) << f.planner << std::right << std::setprecision(1)
                << std::setw(11) << f.ms_median << std::setw(9) << f.ms_p95 << std::setw(11)
                << f.cpu_ms_median << std::setprecision(2) << std::setw(11) << f.length_m
                << std::setw(9) << f.cost << std::setprecision(0) << std::setw(11) << f.expanded
                << std::setw(7) << f.solved << "\n";
    result = 0;
  });
}

}  // namespace tessera::app
