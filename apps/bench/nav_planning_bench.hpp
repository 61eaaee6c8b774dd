// The global-planning benchmark behind `tessera bench planner` (and the planner figures of
// `tessera bench nav`): a synthetic office costmap, and the global planners timed on fixed
// start/goal pairs across it.
//
// The office (makeOfficeCostmap) is deterministic for a seed: outer walls, bands of rooms
// (0.1 m walls) with corridors between them, a door (1 m) in every wall between a room and the
// band beside it, doors in some walls between neighbouring rooms, and desks / pillars inside the
// rooms away from the walls; then inflated with the given options. Start/goal pairs lie
// `pair_distance` apart (straight line) through the map centre at evenly spread bearings, each
// snapped to the nearest free (cost 0) cell.
//
// Planners, each timed as a whole call on warm search buffers: "dijkstra", "astar" (GridPlanner,
// octile heuristic), "astar_landmarks" (with `landmarks` landmark bounds built on the map first,
// their build time reported apart), "astar_los" (that A* then shortenPath), "astar_los_aco" (then
// AntColonyRefiner::refine, which shortens by line of sight first). Repetitions interleave the
// planners so that machine load hits them alike.
#pragma once

#include <tessera/navigation/ant_colony.hpp>
#include <tessera/navigation/costmap.hpp>
#include <tessera/navigation/grid_planner.hpp>
#include <tessera/navigation/landmark_bounds.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace tessera::app {

struct PlanningBenchOptions {
  int cells = 2000;                               ///< map side [cells]
  double resolution = 0.05;                       ///< [m/cell]
  std::uint64_t seed = 7;                         ///< office layout
  int pairs = 4;                                  ///< start/goal pairs
  double pair_distance = 75;                      ///< [m] straight line between start and goal
  int repeat = 5;                                 ///< timed runs per pair and planner
  bool ant_colony = true;                         ///< also time "astar_los_aco" (the slowest)
  int landmarks = navigation::kDefaultLandmarks;  ///< landmark bounds for "astar_landmarks" and the
                                                  ///< LOS/ACO rows; 0: none
  navigation::InflationOptions inflation;         ///< defaults: 0.20 m inscribed, 0.55 m
  navigation::GridPlannerOptions planner;         ///< algorithm is set per planner
  navigation::AntColonyOptions ant_colony_options;

  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

struct PlanningPair {
  Eigen::Vector2i start, goal;  ///< cells
  double straight_m = 0;        ///< [m] centre to centre
};

struct PlannerFigures {
  std::string planner;               ///< "dijkstra", "astar", "astar_los", "astar_los_aco"
  double ms_median = 0, ms_p95 = 0;  ///< wall time over pairs × repetitions
  double cpu_ms_median = 0;          ///< the thread's CPU time, steadier on a loaded machine
  double length_m = 0;               ///< mean over the solved pairs [m]
  /// Mean cost [m, cost-weighted]: the search's cost for dijkstra / astar; for the shortened
  /// paths the same step model (length × (1 + w c / 252)) integrated along the segments.
  double cost = 0;
  double expanded = 0;  ///< mean cells A* / Dijkstra took from the open list per plan
  int solved = 0;       ///< pairs with a path
};

struct PlanningBenchResult {
  int width = 0, height = 0;  ///< [cells]
  double resolution = 0;      ///< [m/cell]
  double map_ms = 0;          ///< building and inflating the costmap
  double landmarks_ms = 0;    ///< building the landmark bounds (0 without)
  std::vector<PlanningPair> pairs;
  std::vector<PlannerFigures> results;
  /// The figures of `planner`, or nullptr when it was not run.
  const PlannerFigures* find(const std::string& planner) const;
};

/// The synthetic office (see the top of this file), inflated.
navigation::Costmap makeOfficeCostmap(int cells, double resolution, std::uint64_t seed,
                                      const navigation::InflationOptions& inflation);

/// Cost of a polyline of cells under the planner's step model, sampled every resolution / 8.
double polylineCost(const navigation::Costmap& map, const std::vector<Eigen::Vector2i>& cells,
                    const navigation::GridPlannerOptions& options);

PlanningBenchResult runPlanningBench(const PlanningBenchOptions& options);

}  // namespace tessera::app
