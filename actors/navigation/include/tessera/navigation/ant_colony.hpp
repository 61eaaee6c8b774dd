// AntColonyRefiner: the thesis's ant-colony refinement of a grid path
// (docs/algorithms.md#global-planning).
//
// Ants leave from cells near the start that the start sees, and walk towards the goal one cell at
// a time, choosing among the three moves that head goal-wards (the octant towards the goal and its
// two neighbours) with probability ∝ τ^α of that (cell, move). An ant stops once it reaches a cell
// from which the goal is in line of sight (the "odour area"). Its path, start → first cell →
// walk → goal, is shortened by line of sight and has length L_k; each (cell, move) it used gains
// Q / L_k, after all pheromone evaporates to ρ τ. The refiner returns the shortest path seen,
// never longer than the (shortened) input path. Deterministic for a given seed.
#pragma once

#include <tessera/navigation/costmap.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace tessera::navigation {

struct AntColonyOptions {
  int ants = 20;  ///< per iteration
  int iterations = 15;
  double evaporation = 0.9;  ///< ρ: pheromone kept per iteration
  double deposit = 1.0;      ///< Q [m]
  double alpha = 1.0;        ///< weight of pheromone in the move choice
  double nest_radius = 1.0;  ///< [m] ants start within this distance of the start
  int max_steps = 5000;      ///< per ant
  int max_cost = 252;        ///< cells an ant or a straight cut may cross (0-252)
  std::uint64_t seed = 1;

  template <class V>
  void visit(V& v) {
    v("ants", ants, "ants per iteration");
    v("iterations", iterations, "iterations");
    v("evaporation", evaporation, "pheromone kept per iteration (rho)");
    v("deposit", deposit, "[m] pheromone Q an ant deposits, divided by its path length");
    v("alpha", alpha, "weight of pheromone in the move choice");
    v("nest_radius", nest_radius, "[m] ants start within this distance of the start");
    v("max_steps", max_steps, "steps before an ant gives up");
    v("max_cost", max_cost, "highest cell cost an ant or a straight cut may cross");
    v("seed", seed, "random seed");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

struct AntColonySummary {
  double input_length = 0;   ///< [m] of the input after line-of-sight shortening
  double output_length = 0;  ///< [m]
  int ants_arrived = 0;      ///< ants that reached the odour area
  int improvements = 0;      ///< times an ant's path beat the best so far
};

class AntColonyRefiner {
 public:
  explicit AntColonyRefiner(const AntColonyOptions& options = {});

  /// Refines `path` (start … goal, e.g. A*'s cells); returns waypoints, start and goal included,
  /// each in line of sight of the next.
  std::vector<Eigen::Vector2i> refine(const Costmap& map, const std::vector<Eigen::Vector2i>& path,
                                      AntColonySummary* summary = nullptr) const;

 private:
  AntColonyOptions options_;
};

}  // namespace tessera::navigation
