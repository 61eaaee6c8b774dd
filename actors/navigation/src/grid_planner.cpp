// GridPlanner: 8-connected Dijkstra / A* over a Costmap, and line-of-sight shortening.
#include <tessera/navigation/grid_planner.hpp>

#include <tessera/config/config_check.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <limits>
#include <queue>

namespace tessera::navigation {

void GridPlannerOptions::validate() const {
  ConfigCheck()
      .nonNegative("cost_weight", cost_weight)
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

GridPlanner::GridPlanner(const GridPlannerOptions& options) : options_(options) {
  options_.validate();
}

bool GridPlanner::passable(std::uint8_t c) const {
  return c <= cost::kMaxTraversable || (c == cost::kUnknown && options_.allow_unknown);
}

double GridPlanner::stepFactor(std::uint8_t c) const {
  const double counted = c == cost::kUnknown ? options_.unknown_cost : c;
  return 1.0 + options_.cost_weight * counted / cost::kMaxTraversable;
}

GridPath GridPlanner::plan(const Costmap& map, const Eigen::Vector2i& start,
                           const Eigen::Vector2i& goal) {
  GridPath out;
  if (!map.contains(start)) return out.status = PlanStatus::kStartOutside, out;
  if (!map.contains(goal)) return out.status = PlanStatus::kGoalOutside, out;
  if (!passable(map.at(start))) return out.status = PlanStatus::kStartBlocked, out;
  if (!passable(map.at(goal))) return out.status = PlanStatus::kGoalBlocked, out;

  constexpr double kInf = std::numeric_limits<double>::infinity();
  const std::size_t n = map.cells.size();
  if (g_.size() != n) {
    g_.assign(n, kInf);
    parent_.assign(n, -1);
    state_.assign(n, 0);
    touched_.clear();
  } else {
    for (const std::int32_t i : touched_) {
      g_[static_cast<std::size_t>(i)] = kInf;
      parent_[static_cast<std::size_t>(i)] = -1;
      state_[static_cast<std::size_t>(i)] = 0;
    }
    touched_.clear();
  }

  const int w = map.width, h = map.height;
  const double res = map.resolution, diag = std::sqrt(2.0) * res;
  const bool astar = options_.algorithm == SearchAlgorithm::kAStar;
  auto heuristic = [&](int col, int row) {
    if (!astar) return 0.0;
    const int dx = std::abs(col - goal.x()), dy = std::abs(row - goal.y());
    return res * (std::max(dx, dy) - std::min(dx, dy)) + diag * std::min(dx, dy);
  };
  // Step cost factor per cell cost (negative = impassable), looked up rather than recomputed.
  std::array<double, 256> factor{};
  for (int c = 0; c < 256; ++c)
    factor[static_cast<std::size_t>(c)] =
        passable(static_cast<std::uint8_t>(c)) ? stepFactor(static_cast<std::uint8_t>(c)) : -1.0;
  // Equal f: the deeper entry first. On open floor many cells tie, and preferring the one
  // closest to the goal walks straight there instead of widening the whole tie front.
  struct Entry {
    double f, g;
    std::int32_t i;
    bool operator>(const Entry& o) const { return f > o.f || (f == o.f && g < o.g); }
  };
  std::priority_queue<Entry, std::vector<Entry>, std::greater<>> open;
  const auto s = static_cast<std::int32_t>(map.index(start.x(), start.y()));
  const auto t = static_cast<std::int32_t>(map.index(goal.x(), goal.y()));
  g_[static_cast<std::size_t>(s)] = 0;
  touched_.push_back(s);
  open.push({heuristic(start.x(), start.y()), 0.0, s});

  static constexpr int kDx[8] = {1, -1, 0, 0, 1, 1, -1, -1};
  static constexpr int kDy[8] = {0, 0, 1, -1, 1, -1, 1, -1};
  const std::uint8_t* cells = map.cells.data();
  while (!open.empty()) {
    const Entry top = open.top();
    open.pop();
    const auto ui = static_cast<std::size_t>(top.i);
    if (state_[ui] == 2) continue;  // a stale entry of a cell already closed
    state_[ui] = 2;
    ++out.expanded;
    if (top.i == t) break;
    const int col = top.i % w, row = top.i / w;
    const double g0 = g_[ui];
    for (int k = 0; k < 8; ++k) {
      const int nc = col + kDx[k], nr = row + kDy[k];
      if (nc < 0 || nr < 0 || nc >= w || nr >= h) continue;
      const std::size_t ni =
          static_cast<std::size_t>(nr) * static_cast<std::size_t>(w) + static_cast<std::size_t>(nc);
      const double f = factor[cells[ni]];
      if (f < 0 || state_[ni] == 2) continue;
      // No diagonal squeezes between two blocked cells.
      if (k >= 4 && (factor[cells[static_cast<std::size_t>(row) * w + nc]] < 0 ||
                     factor[cells[static_cast<std::size_t>(nr) * w + col]] < 0))
        continue;
      const double g = g0 + (k < 4 ? res : diag) * f;
      if (g >= g_[ni]) continue;
      if (state_[ni] == 0) touched_.push_back(static_cast<std::int32_t>(ni));
      state_[ni] = 1;
      g_[ni] = g;
      parent_[ni] = top.i;
      open.push({g + heuristic(nc, nr), g, static_cast<std::int32_t>(ni)});
    }
  }
  if (state_[static_cast<std::size_t>(t)] != 2) return out.status = PlanStatus::kNoPath, out;

  for (std::int32_t i = t; i >= 0; i = parent_[static_cast<std::size_t>(i)])
    out.cells.emplace_back(i % w, i / w);
  std::reverse(out.cells.begin(), out.cells.end());
  out.status = PlanStatus::kOk;
  out.cost = g_[static_cast<std::size_t>(t)];
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
                 std::uint8_t max_cost) {
  if (!map.contains(a) || !map.contains(b)) return false;
  auto clear = [&](int col, int row) { return map.at(col, row) <= max_cost; };
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
