// LandmarkBounds: lower bounds on GridPlanner's path costs from a few landmark cells (the "ALT"
// heuristic: A*, landmarks, triangle inequality; docs/algorithms.md#landmark-bounds).
//
// Built once from a reference costmap (the static map, inflated): for each landmark L the exact
// search cost d(L, x) from L to every cell and d(x, L) from every cell to L, in GridPlanner's
// integer units under the given planner options. For any map whose every step costs at least as
// much as in the reference (obstacles added, costs raised: holdsFor() checks it cell by cell),
// the triangle inequality gives cost(x → g) >= d(L, g) − d(L, x) and >= d(x, L) − d(g, L), and
// both are consistent heuristics, so A* with them stays exact and can keep its bucket queue.
// Landmarks are picked farthest-first (each the reachable cell farthest from those before), so
// they sit at the ends of corridors and rooms, behind or beyond most start/goal pairs.
//
// Memory: 8 · count bytes per cell (a 2000 × 2000 map with 4 landmarks: 128 MB), from
// LargePageAllocator, interleaved per cell so one cache line serves a cell's bounds.
// Immutable once built; share it between planners (GridPlanner::setLandmarks).
#pragma once

#include <tessera/memory/large_page_allocator.hpp>
#include <tessera/navigation/costmap.hpp>
#include <tessera/navigation/grid_planner.hpp>

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace tessera::navigation {

/// Landmarks the navigator and the planning benchmark use unless told otherwise: on a
/// 2000 × 2000 office 8 take A* to ~0.5× of its octile time (16: ~0.4×, at twice the memory).
inline constexpr int kDefaultLandmarks = 8;

class LandmarkBounds {
 public:
  /// Marks a cell that cannot reach (or be reached from) a landmark.
  static constexpr std::uint32_t kUnreachable = std::numeric_limits<std::uint32_t>::max();

  /// `count` (1-16) landmarks on `reference` under `options`' cost model (the algorithm field is
  /// ignored). Throws std::invalid_argument on a bad count or a map without a passable cell,
  /// std::overflow_error when a cost exceeds 32 bits.
  LandmarkBounds(const Costmap& reference, const GridPlannerOptions& options, int count);

  /// Whether the bounds hold for `map` searched under `options`: same size and cost model, and
  /// no step in `map` cheaper than in the reference (a cell cleared below its reference cost,
  /// or unknown allowed where the reference had none, breaks them).
  bool holdsFor(const Costmap& map, const GridPlannerOptions& options) const;
  /// The same for a planner's step costs (GridPlanner checks every plan with its own).
  bool holdsFor(const Costmap& map, const StepCosts& steps) const;

  int count() const { return count_; }
  const std::vector<Eigen::Vector2i>& landmarks() const { return landmarks_; }
  int width() const { return width_; }
  int height() const { return height_; }

  /// d(landmark, cell) [units], kUnreachable if none; cell is a row-major index.
  std::uint32_t from(int landmark, std::size_t cell) const {
    return dist_[cell * stride() + static_cast<std::size_t>(landmark)];
  }
  /// d(cell, landmark) [units], kUnreachable if none.
  std::uint32_t to(int landmark, std::size_t cell) const {
    return dist_[cell * stride() + static_cast<std::size_t>(count_ + landmark)];
  }
  /// A cell's 2 · count values: from(0 … count − 1), then to(0 … count − 1).
  const std::uint32_t* row(std::size_t cell) const { return dist_.data() + cell * stride(); }

 private:
  std::size_t stride() const { return 2 * static_cast<std::size_t>(count_); }

  int count_ = 0;
  int width_ = 0, height_ = 0;
  StepCosts steps_;
  std::vector<std::uint8_t> reference_;
  std::array<std::uint16_t, 256> rank_{};  ///< a cell cost as the step model orders it
  std::vector<Eigen::Vector2i> landmarks_;
  memory::LargePageVector<std::uint32_t> dist_;
};

/// Exact search costs [units] from `source` to every cell (reverse: from every cell to
/// `source`), LandmarkBounds::kUnreachable where there is no path: GridPlanner's step model,
/// one Dijkstra over the whole map. Throws std::overflow_error beyond 32 bits.
std::vector<std::uint32_t> costsFrom(const Costmap& map, const StepCosts& steps,
                                     const Eigen::Vector2i& source, bool reverse = false);

}  // namespace tessera::navigation
