// GridPlanner: global paths on a Costmap by 8-connected Dijkstra or A*
// (docs/algorithms.md#global-planning), and line-of-sight shortening of a path.
//
// A step between neighbouring cells costs its length [m] (resolution, or √2 · resolution
// diagonally) times 1 + cost_weight · c / 252, c being the cost of the cell entered, so paths
// keep away from inflated obstacles when the detour is cheap. Cells at kInscribed and above are
// never entered (kUnknown only with allow_unknown, at unknown_cost). A*'s heuristic is the octile
// distance, a lower bound of that cost, so A* returns a path as cheap as Dijkstra's. The search
// adds integer step costs (kStraightUnits per cell side and kDiagonalUnits per diagonal, their
// ratio √2 within 1e-5, each times the cell's factor, rounded): equal costs compare equal, A*'s
// and Dijkstra's costs agree exactly, and the open list is a bucket queue
// (docs/algorithms.md#global-planning). GridPath::cost converts back to metres.
//
// The planner keeps its search buffers between calls (one per map size): one planner per thread.
#pragma once

#include <tessera/memory/large_page_allocator.hpp>
#include <tessera/navigation/bucket_queue.hpp>
#include <tessera/navigation/costmap.hpp>

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string_view>
#include <utility>
#include <vector>

namespace tessera::navigation {

enum class SearchAlgorithm { kAStar, kDijkstra };
constexpr std::array<std::pair<const char*, SearchAlgorithm>, 2> optionNames(SearchAlgorithm) {
  return {{{"astar", SearchAlgorithm::kAStar}, {"dijkstra", SearchAlgorithm::kDijkstra}}};
}

struct GridPlannerOptions {
  SearchAlgorithm algorithm = SearchAlgorithm::kAStar;
  double cost_weight = 3.0;  ///< a step into cost 252 costs (1 + cost_weight) × its length; <= 100
  bool allow_unknown = false;  ///< may paths cross kUnknown cells
  int unknown_cost = 128;      ///< the cost an unknown cell counts as, when allowed

  template <class V>
  void visit(V& v) {
    v("algorithm", algorithm, "graph search");
    v("cost_weight", cost_weight,
      "extra cost factor of a step into the highest traversable cost (at most 100)");
    v("allow_unknown", allow_unknown, "may paths cross unknown cells");
    v("unknown_cost", unknown_cost, "cost (0-252) of an unknown cell when allowed");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

enum class PlanStatus { kOk, kStartOutside, kGoalOutside, kStartBlocked, kGoalBlocked, kNoPath };
std::string_view statusName(PlanStatus status);

struct GridPath {
  PlanStatus status = PlanStatus::kNoPath;
  std::vector<Eigen::Vector2i> cells;  ///< start … goal; empty unless kOk
  double cost = 0;                     ///< the search's cost of the path [m, cost-weighted]
  double length = 0;                   ///< [m] geometric length
  std::size_t expanded = 0;            ///< cells taken from the open list
  bool landmarks_used = false;         ///< A* had landmark bounds for this map
  bool ok() const { return status == PlanStatus::kOk; }
};

/// Integer cost units of a straight and a diagonal step at factor 1 (239 / 169 = √2 − 1.2e-5);
/// a factor is rounded to 1/169 of a step (docs/algorithms.md#global-planning says why so coarse).
inline constexpr std::int64_t kStraightUnits = 169;
inline constexpr std::int64_t kDiagonalUnits = 239;

/// Integer step costs into a cell, per cell cost, under a planner's options (0: never entered).
struct StepCosts {
  std::array<std::int64_t, 256> straight{}, diagonal{};
  std::int64_t max_step = 0;  ///< the largest diagonal step
  bool operator==(const StepCosts&) const = default;
};
StepCosts stepCosts(const GridPlannerOptions& options);

class LandmarkBounds;

class GridPlanner {
 public:
  explicit GridPlanner(const GridPlannerOptions& options = {});

  GridPath plan(const Costmap& map, const Eigen::Vector2i& start, const Eigen::Vector2i& goal);

  /// A* also takes the landmark bounds (landmark_bounds.hpp) as its heuristic, on every map they
  /// hold for (checked per plan; elsewhere the octile distance alone). nullptr: none.
  void setLandmarks(std::shared_ptr<const LandmarkBounds> landmarks);
  const std::shared_ptr<const LandmarkBounds>& landmarks() const { return landmarks_; }

  const GridPlannerOptions& options() const { return options_; }

 private:
  GridPlannerOptions options_;
  StepCosts steps_;
  std::shared_ptr<const LandmarkBounds> landmarks_;
  /// Search state per cell, row-major, reused between plans. mark_: 2 · generation while open,
  /// 2 · generation + 1 once closed (one byte per cell, so the marks of the searched region stay
  /// in cache); g_: the cost from the start [units], valid where marked in this plan. A plan
  /// bumps the generation instead of resetting the cells the last one touched; the path is read
  /// back from the g values, so no parent is stored.
  memory::LargePageVector<std::uint8_t> mark_;
  memory::LargePageVector<std::uint32_t> g_;
  std::uint8_t generation_ = 0;
  MonotoneBucketQueue open_;
};

/// Geometric length [m] of a cell path (centre to centre).
double pathLength(const Costmap& map, const std::vector<Eigen::Vector2i>& cells);

/// Whether the straight segment between the centres of a and b crosses only cells of cost
/// <= max_cost (every cell the segment touches, corners included); with unknown_clear, unknown
/// cells count as clear too (a path planned through unknown space is not blocked by it).
bool lineOfSight(const Costmap& map, const Eigen::Vector2i& a, const Eigen::Vector2i& b,
                 std::uint8_t max_cost, bool unknown_clear = false);

/// Line-of-sight shortening: from the first cell, jump to the last path cell visible from it,
/// and repeat from there. Returns the kept cells (start and goal included); consecutive kept
/// cells see each other under max_cost.
std::vector<Eigen::Vector2i> shortenPath(const Costmap& map,
                                         const std::vector<Eigen::Vector2i>& path,
                                         std::uint8_t max_cost);

}  // namespace tessera::navigation
