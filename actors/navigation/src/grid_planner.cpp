// GridPlanner: 8-connected Dijkstra / A* over a Costmap (integer costs, a bucket queue), and
// line-of-sight shortening.
#include <tessera/navigation/grid_planner.hpp>

#include <tessera/config/config_check.hpp>
#include <tessera/navigation/landmark_bounds.hpp>

#include "grid_moves.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace tessera::navigation {

void GridPlannerOptions::validate() const {
  ConfigCheck()
      .nonNegative("cost_weight", cost_weight)
      .require(cost_weight <= 100, "cost_weight", "must be <= 100", cost_weight)
      .require(unknown_cost >= 0 && unknown_cost <= cost::kMaxTraversable, "unknown_cost",
               "must be in [0, 252]", unknown_cost)
      .throwIfBad("grid planner");
}

std::string_view statusName(PlanStatus status) {
  switch (status) {
    case PlanStatus::kOk:
      return "ok";
    case PlanStatus::kStartOutside:
      return "start outside the map";
    case PlanStatus::kGoalOutside:
      return "goal outside the map";
    case PlanStatus::kStartBlocked:
      return "start in an obstacle";
    case PlanStatus::kGoalBlocked:
      return "goal in an obstacle";
    case PlanStatus::kNoPath:
      return "no path";
  }
  return "?";
}

StepCosts stepCosts(const GridPlannerOptions& options) {
  StepCosts out;
  for (int c = 0; c < 256; ++c) {
    const auto b = static_cast<std::uint8_t>(c);
    const bool unknown = b == cost::kUnknown;
    if (!(b <= cost::kMaxTraversable || (unknown && options.allow_unknown))) continue;
    const double counted = unknown ? options.unknown_cost : b;
    const double factor = 1.0 + options.cost_weight * counted / cost::kMaxTraversable;
    out.straight[static_cast<std::size_t>(c)] = std::llround(kStraightUnits * factor);
    out.diagonal[static_cast<std::size_t>(c)] = std::llround(kDiagonalUnits * factor);
  }
  out.max_step = *std::max_element(out.diagonal.begin(), out.diagonal.end());
  return out;
}

GridPlanner::GridPlanner(const GridPlannerOptions& options)
    : options_(options), steps_((options.validate(), stepCosts(options))) {}

void GridPlanner::setLandmarks(std::shared_ptr<const LandmarkBounds> landmarks) {
  landmarks_ = std::move(landmarks);
}

namespace {

// Marks are 2 · generation (open) and 2 · generation + 1 (closed) in a byte.
constexpr std::uint8_t kMaxGeneration = 127;
constexpr std::int64_t kMaxG = std::numeric_limits<std::uint32_t>::max();

using moves::kDx;
using moves::kDy;
using moves::kSideX;
using moves::kSideY;

}  // namespace

GridPath GridPlanner::plan(const Costmap& map, const Eigen::Vector2i& start,
                           const Eigen::Vector2i& goal) {
  GridPath out;
  if (!map.contains(start)) return out.status = PlanStatus::kStartOutside, out;
  if (!map.contains(goal)) return out.status = PlanStatus::kGoalOutside, out;
  const auto& straight = steps_.straight;
  const auto& diagonal = steps_.diagonal;
  const std::int64_t max_step = steps_.max_step;
  if (straight[map.at(start)] == 0) return out.status = PlanStatus::kStartBlocked, out;
  if (straight[map.at(goal)] == 0) return out.status = PlanStatus::kGoalBlocked, out;

  const std::size_t n = map.cells.size();
  if (n > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max()))
    throw std::invalid_argument("grid planner: a map of " + std::to_string(n) +
                                " cells is too large (cells are indexed by int32)");
  if (mark_.size() != n) {
    mark_.assign(n, 0);
    g_.assign(n, 0);
    generation_ = 0;
  }
  if (generation_ == kMaxGeneration) {
    std::fill(mark_.begin(), mark_.end(), 0);  // marks would wrap: start over
    generation_ = 0;
  }
  ++generation_;
  const auto open_mark = static_cast<std::uint8_t>(2 * generation_);
  const auto closed_mark = static_cast<std::uint8_t>(open_mark + 1);

  const int w = map.width, h = map.height;
  const bool astar = options_.algorithm == SearchAlgorithm::kAStar;
  const int goal_col = goal.x(), goal_row = goal.y();
  const auto t = static_cast<std::int32_t>(map.index(goal.x(), goal.y()));

  // Landmark bounds, where they hold for this map.
  const LandmarkBounds* lm =
      astar && landmarks_ && landmarks_->holdsFor(map, steps_) ? landmarks_.get() : nullptr;
  // Per landmark L the goal reaches, two terms: d(L, goal) − d(L, x) and d(x, L) − d(goal, L),
  // each sign · (base − the cell's value in `column`): one flat loop over the terms measured
  // faster than two loads per landmark (docs/benchmarks.md). A cell that cannot reach such a
  // landmark cannot reach the goal either (the reference passes wherever this map does): it is
  // never pushed.
  std::array<int, 32> column{};
  std::array<std::int64_t, 32> base{}, sign{};
  int terms = 0;
  int prune_column = -1;
  if (lm) {
    const int k = lm->count();
    const std::uint32_t* at_goal = lm->row(static_cast<std::size_t>(t));
    for (int j = 0; j < k; ++j) {
      if (at_goal[k + j] == LandmarkBounds::kUnreachable) continue;  // landmark elsewhere
      if (prune_column < 0) prune_column = k + j;
      for (const int c : {j, k + j}) {
        const auto u = static_cast<std::size_t>(terms++);
        column[u] = c;
        sign[u] = c < k ? 1 : -1;
        base[u] = at_goal[c];
      }
    }
    out.landmarks_used = terms > 0;
  }
  constexpr std::int64_t kPrune = -1;
  // The octile distance (and the landmark bounds) in the step units at factor 1 never exceed a
  // step's cost: consistent, exactly.
  auto heuristic = [&](std::int32_t vi, int col, int row) -> std::int64_t {
    if (!astar) return 0;
    const std::int64_t dx = std::abs(col - goal_col), dy = std::abs(row - goal_row);
    const std::int64_t lo = std::min(dx, dy), hi = std::max(dx, dy);
    std::int64_t best = kStraightUnits * (hi - lo) + kDiagonalUnits * lo;
    if (prune_column < 0) return best;
    const std::uint32_t* bound = lm->row(static_cast<std::size_t>(vi));
    if (bound[prune_column] == LandmarkBounds::kUnreachable) return kPrune;
    for (int i = 0; i < terms; ++i) {
      const auto u = static_cast<std::size_t>(i);
      best = std::max(best, sign[u] * (base[u] - std::int64_t{bound[column[u]]}));
    }
    return best;
  };
  // A push's f exceeds the last popped one by at most a step plus the heuristic's rise, which
  // is at most a diagonal step at factor 1 for the octile distance, and at most a step for a
  // landmark bound (the triangle inequality once more).
  open_.reset(max_step + (lm ? max_step : (astar ? kDiagonalUnits : 0)));

  std::uint8_t* mark = mark_.data();
  std::uint32_t* gs = g_.data();
  const std::uint8_t* cells = map.cells.data();
  const auto s = static_cast<std::int32_t>(map.index(start.x(), start.y()));
  mark[s] = open_mark;
  gs[s] = 0;
  const std::int64_t h0 = heuristic(s, start.x(), start.y());
  if (h0 == kPrune) {
    open_.clear();
    return out.status = PlanStatus::kNoPath, out;
  }
  open_.push(h0, s);
  std::int32_t offset[8];
  for (int k = 0; k < 8; ++k) offset[k] = kDy[k] * w + kDx[k];

  // Keys are exact, so cells pop in order of f; among equal f the last reached first, which
  // walks straight on across open floor rather than widening the whole front of equal f. An
  // entry of a cell already closed is stale (a cheaper entry of it came first): skipped.
  while (!open_.empty()) {
    const std::int32_t ui = open_.pop().value;
    if (mark[ui] == closed_mark) continue;
    mark[ui] = closed_mark;
    ++out.expanded;
    if (ui == t) break;
    const std::int64_t g0 = gs[ui];
    if (g0 > kMaxG - max_step)
      throw std::overflow_error("grid planner: path cost exceeds the search's range");
    const int col = ui % w, row = ui / w;
    // Away from the border every neighbour exists; at the border one outside the map counts as
    // blocked (and reads the cell itself, a safe index). Whether a neighbour improves is decided
    // without branches (a closed one, or an open one at no lower cost, is dropped by not
    // advancing the candidate count): these outcomes are close to random on a map, and the
    // branch-free form took Dijkstra's time to ~0.8x (A*'s stayed within the noise). One body,
    // compiled twice: the interior instance has no bounds checks at all.
    const auto expand = [&](auto interior) {
      std::int32_t candidate[8];
      std::int64_t candidate_g[8];
      int move[8];
      int count = 0;
      bool open_side[4];
      for (int k = 0; k < 8; ++k) {
        const bool inside = decltype(interior)::value || map.contains(col + kDx[k], row + kDy[k]);
        const std::int32_t vi = inside ? ui + offset[k] : ui;
        std::int64_t step = inside ? (k < 4 ? straight : diagonal)[cells[vi]] : 0;
        if (k < 4)
          open_side[k] = step != 0;
        else
          step = open_side[kSideX[k]] && open_side[kSideY[k]] ? step : 0;
        const std::uint8_t m = mark[vi];
        const std::int64_t g = g0 + step;
        const bool better =
            (step != 0) & (m != closed_mark) & ((m != open_mark) | (g < std::int64_t{gs[vi]}));
        candidate[count] = vi;
        candidate_g[count] = g;
        move[count] = k;
        count += better ? 1 : 0;
      }
      for (int i = 0; i < count; ++i) {
        const std::int32_t vi = candidate[i];
        const std::int64_t hv = heuristic(vi, col + kDx[move[i]], row + kDy[move[i]]);
        if (hv == kPrune) continue;
        mark[vi] = open_mark;
        gs[vi] = static_cast<std::uint32_t>(candidate_g[i]);
        open_.push(candidate_g[i] + hv, vi);
      }
    };
    if (col > 0 && row > 0 && col + 1 < w && row + 1 < h)
      expand(std::true_type{});
    else
      expand(std::false_type{});
  }
  open_.clear();
  if (mark[t] != closed_mark) return out.status = PlanStatus::kNoPath, out;

  // Back from the goal: a neighbour reached in this plan whose g plus the step equals the
  // cell's g is a predecessor on a cheapest path (the cell's g was set exactly so from one).
  auto reached = [&](std::int32_t i) { return mark[i] == open_mark || mark[i] == closed_mark; };
  std::int32_t ci = t;
  out.cells.emplace_back(goal);
  while (ci != s) {
    const int col = ci % w, row = ci / w;
    const std::int64_t g = gs[ci];
    bool open_side[4] = {false, false, false, false};
    for (int k = 0; k < 4; ++k) {
      const int nc = col + kDx[k], nr = row + kDy[k];
      open_side[k] = map.contains(nc, nr) && straight[cells[ci + offset[k]]] != 0;
    }
    std::int32_t previous = -1;
    for (int k = 0; k < 8 && previous < 0; ++k) {
      // The step from the neighbour into ci costs by ci's cell; a diagonal one needs both sides.
      if (k < 4 ? !open_side[k] : (!open_side[kSideX[k]] || !open_side[kSideY[k]])) continue;
      const std::int32_t pi = ci + offset[k];
      const std::int64_t step = (k < 4 ? straight : diagonal)[cells[ci]];
      if (reached(pi) && std::int64_t{gs[pi]} + step == g) previous = pi;
    }
    if (previous < 0) throw std::logic_error("grid planner: no predecessor while reading back");
    ci = previous;
    out.cells.emplace_back(ci % w, ci / w);
  }
  std::reverse(out.cells.begin(), out.cells.end());
  out.status = PlanStatus::kOk;
  out.cost = static_cast<double>(gs[t]) / static_cast<double>(kStraightUnits) * map.resolution;
  out.length = pathLength(map, out.cells);
  return out;
}

double pathLength(const Costmap& map, const std::vector<Eigen::Vector2i>& cells) {
  double length = 0;
  for (std::size_t i = 1; i < cells.size(); ++i)
    length += (cells[i] - cells[i - 1]).cast<double>().norm() * map.resolution;
  return length;
}

bool lineOfSight(const Costmap& map, const Eigen::Vector2i& a, const Eigen::Vector2i& b,
                 std::uint8_t max_cost, bool unknown_clear) {
  if (!map.contains(a) || !map.contains(b)) return false;
  auto clear = [&](int col, int row) {
    const std::uint8_t c = map.at(col, row);
    return c <= max_cost || (unknown_clear && c == cost::kUnknown);
  };
  int col = a.x(), row = a.y();
  if (!clear(col, row)) return false;
  const int sx = b.x() > a.x() ? 1 : (b.x() < a.x() ? -1 : 0);
  const int sy = b.y() > a.y() ? 1 : (b.y() < a.y() ? -1 : 0);
  const long nx = std::abs(b.x() - a.x()), ny = std::abs(b.y() - a.y());
  // Walk the cells the centre-to-centre segment crosses: the next boundary is a vertical one
  // when (ix + 1/2) / nx < (iy + 1/2) / ny. Through a corner both side cells count.
  for (long ix = 0, iy = 0; ix < nx || iy < ny;) {
    const long lhs = (1 + 2 * ix) * ny, rhs = (1 + 2 * iy) * nx;
    if (lhs == rhs) {
      if (!clear(col + sx, row) || !clear(col, row + sy)) return false;
      col += sx;
      row += sy;
      ++ix;
      ++iy;
    } else if (lhs < rhs) {
      col += sx;
      ++ix;
    } else {
      row += sy;
      ++iy;
    }
    if (!clear(col, row)) return false;
  }
  return true;
}

std::vector<Eigen::Vector2i> shortenPath(const Costmap& map,
                                         const std::vector<Eigen::Vector2i>& path,
                                         std::uint8_t max_cost) {
  if (path.size() <= 2) return path;
  std::vector<Eigen::Vector2i> out{path.front()};
  std::size_t i = 0;
  while (i + 1 < path.size()) {
    std::size_t j = i + 1;  // the next cell always stays reachable: the path steps to it
    while (j + 1 < path.size() && lineOfSight(map, path[i], path[j + 1], max_cost)) ++j;
    out.push_back(path[j]);
    i = j;
  }
  return out;
}

}  // namespace tessera::navigation
