// LikelihoodField: the likelihood-field range sensor model on an occupancy map
// (docs/algorithms.md#monte-carlo-localisation).
//
// A beam endpoint at map distance d from the nearest occupied cell has probability
//   p = z_hit · N(d; 0, sigma_hit) + z_rand / range_max
// (d capped at max_distance; endpoints off the map or on unknown cells count as d = max_distance).
// d is the distance to the nearest obstacle surface, interpolated bilinearly between cell
// centres: 0 on a wall's face where a beam ends. Inside an obstacle it is 0, or with
// penalise_inside the depth below the surface: on a sharp map (a simulator's, a floor plan) a
// field that is 0 inside walls pulls the estimate several centimetres towards the walls ahead,
// while on a SLAM map, whose walls are bands blurred over several cells, the depth penalty
// punishes good endpoints (docs/algorithms.md#monte-carlo-localisation).
// Beams at or beyond range_max carry no endpoint and are left out by the caller. The field of
// log p is precomputed per cell from the map's distance transform. Points are robot-frame [m],
// poses map-frame [m, rad]. Immutable after construction: safe to share between threads.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>

#include <Eigen/Core>

#include <span>
#include <vector>

namespace tessera::localization {

struct LikelihoodFieldOptions {
  double sigma_hit = 0.2;        ///< [m] endpoint noise
  double z_hit = 0.95;           ///< weight of the hit component
  double z_rand = 0.05;          ///< weight of the uniform component
  double max_distance = 2.0;     ///< [m] distances are capped here
  int occupied_threshold = 65;   ///< [%] cells at or above this are obstacles
  bool penalise_inside = false;  ///< endpoints inside obstacles count their depth (sharp maps)

  template <class V>
  void visit(V& v) {
    v("sigma_hit", sigma_hit, "[m] beam endpoint noise");
    v("z_hit", z_hit, "weight of the Gaussian hit component");
    v("z_rand", z_rand, "weight of the uniform random component");
    v("max_distance", max_distance, "[m] obstacle distances are capped at this");
    v("occupied_threshold", occupied_threshold, "[%] occupancy at which a cell is an obstacle");
    v("penalise_inside", penalise_inside,
      "endpoints inside obstacles count their depth below the surface (for sharp maps)");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

class LikelihoodField {
 public:
  /// Throws std::invalid_argument for an empty or inconsistent map or bad options.
  LikelihoodField(const grid::OccupancyMap& map, double range_max,
                  const LikelihoodFieldOptions& options = {});

  /// Σ log p over the endpoints `points` (robot frame) seen from `pose`.
  double logLikelihood(const Pose2& pose, std::span<const Eigen::Vector2d> points) const;
  /// [m] distance from point p (map frame) to the nearest obstacle, capped at max_distance.
  double distance(const Eigen::Vector2d& p) const;
  /// Whether a map-frame point lies on a known free cell (where a robot may be).
  bool isFree(const Eigen::Vector2d& p) const;

  const grid::OccupancyMap& map() const { return map_; }
  double rangeMax() const { return range_max_; }

 private:
  grid::OccupancyMap map_;
  LikelihoodFieldOptions options_;
  double range_max_;
  static constexpr double kTableStep = 0.001;  // [m] of the log p table
  std::vector<float> edge_;      // per cell [m]: signed distance to the nearest surface, capped
  std::vector<float> distance_;  // per cell [m], centre to centre, capped
  std::vector<float> table_;     // log p by distance, every kTableStep
  float log_p_far_;              // log p at max_distance (off-map endpoints)
};

}  // namespace tessera::localization
