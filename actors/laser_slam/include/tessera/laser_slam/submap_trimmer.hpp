// SubmapTrimmer: lifelong mapping's rule for which submaps are no longer needed
// (docs/algorithms.md#lifelong-mapping). A robot that loops through the same building makes new
// submaps over the same floor every lap; without trimming, their number (the graph, the loop
// detector's search set, the assembled map's inputs) grows with the hours driven.
//
// Each finished submap is reduced to its footprint: the centres of the coarse cells
// (cell_size) in which its grid knows at least one cell, in the submap's frame. At trim(), every
// footprint is placed at its submap's current pose and every coarse cell goes to the newest
// submap (largest id) that covers it: the newest view of the place wins, so a changed room is
// kept as it is now. A submap that owns less than min_own_fraction of its footprint is covered
// by newer ones and is trimmed; the `keep_newest` newest submaps and the protected ones (the
// graph's anchor) never are. A submap without a pose is left alone.
// Frames: footprints in the submap frame, poses of submap origins in the map frame; metres.
// Plain C++ over Eigen; not thread-safe (one actor owns it).
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace tessera::laser_slam {

struct SubmapTrimmerOptions {
  double cell_size = 0.5;
  double min_own_fraction = 0.1;
  int keep_newest = 2;

  template <class V>
  void visit(V& v) {
    v("cell_size", cell_size, "[m] coverage cells: coarser than the grids, finer than a room");
    v("min_own_fraction", min_own_fraction,
      "a submap owning (newest to cover) less than this fraction of its footprint is trimmed "
      "(0..1)");
    v("keep_newest", keep_newest, "newest finished submaps never trimmed (>= 1)");
  }
};

class SubmapTrimmer {
 public:
  /// Throws std::invalid_argument naming the option when one is out of range.
  explicit SubmapTrimmer(SubmapTrimmerOptions options = {});

  /// The footprint of `grid` (cells in the submap frame): centres of the coarse cells holding
  /// at least one known cell.
  std::vector<Eigen::Vector2d> footprint(const tessera::grid::OccupancyMap& grid) const;

  /// A finished submap and its footprint (replaces an earlier one with the same id).
  void addSubmap(int id, std::vector<Eigen::Vector2d> footprint);
  /// Trims the submaps newer ones cover, placed at `poses` (map frame, by id); never one in
  /// `keep`. Returns their ids, oldest first; they are forgotten here.
  std::vector<int> trim(const std::map<int, tessera::Pose2>& poses, const std::set<int>& keep);

  std::size_t size() const { return footprints_.size(); }
  /// Footprint points held (memory: 16 bytes each).
  std::size_t points() const;

 private:
  SubmapTrimmerOptions options_;
  std::map<int, std::vector<Eigen::Vector2d>> footprints_;
};

}  // namespace tessera::laser_slam
