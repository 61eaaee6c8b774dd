// Map quality against true walls: see map_metrics.hpp.
#include <tessera/evaluation/map_metrics.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

namespace tessera::evaluation {

namespace {

Eigen::Vector2d closestOnSegment(const Eigen::Vector2d& p, const WallSegment& w) {
  const Eigen::Vector2d d = w.b - w.a;
  const double len2 = d.squaredNorm();
  return w.a + (len2 > 0 ? std::clamp((p - w.a).dot(d) / len2, 0.0, 1.0) : 0.0) * d;
}

/// The point of the walls nearest to p.
Eigen::Vector2d closestOnWalls(const Eigen::Vector2d& p, const std::vector<WallSegment>& walls) {
  Eigen::Vector2d best = p;
  double best_d = std::numeric_limits<double>::infinity();
  for (const auto& w : walls) {
    const Eigen::Vector2d q = closestOnSegment(p, w);
    const double d = (q - p).norm();
    if (d < best_d) best_d = d, best = q;
  }
  return best;
}

/// Map-frame centre of cell (col, row).
Eigen::Vector2d cellCentre(const grid::OccupancyMap& m, int col, int row) {
  return m.origin * Eigen::Vector2d((col + 0.5) * m.resolution, (row + 0.5) * m.resolution);
}

/// Whether any cell whose centre is within tolerance (+ half a cell) of p is known, and whether
/// any is occupied.
struct Near {
  bool known = false, occupied = false;
};
/// `to_grid` is map.origin's inverse, computed once by the caller.
Near lookNear(const grid::OccupancyMap& map, const Pose2& to_grid, const Eigen::Vector2d& p,
              const MapWallOptions& options) {
  const int reach = static_cast<int>(std::ceil(options.tolerance_m / map.resolution));
  const Eigen::Vector2d g = to_grid * p / map.resolution;
  const int c0 = static_cast<int>(std::floor(g.x())), r0 = static_cast<int>(std::floor(g.y()));
  Near n;
  for (int r = r0 - reach; r <= r0 + reach && !n.occupied; ++r)
    for (int c = c0 - reach; c <= c0 + reach && !n.occupied; ++c) {
      if (!map.contains(c, r)) continue;
      const std::int8_t v = map.at(c, r);
      if (v < 0) continue;
      if ((cellCentre(map, c, r) - p).norm() > options.tolerance_m + 0.5 * map.resolution) continue;
      n.known = true;
      if (v >= options.occupied_threshold) n.occupied = true;
    }
  return n;
}

}  // namespace

MapWallScore scoreMapAgainstWalls(const grid::OccupancyMap& map,
                                  const std::vector<WallSegment>& walls,
                                  const MapWallOptions& options) {
  if (map.empty()) throw std::invalid_argument("map quality: the map is empty");
  if (!(options.tolerance_m > 0) || !(options.doubled_range_m > 0))
    throw std::invalid_argument("map quality: tolerance_m and doubled_range_m must be > 0");
  MapWallScore s;
  const Pose2 to_grid = map.origin.inverse();
  for (const auto& w : walls) {
    const double len = (w.b - w.a).norm();
    const int n = std::max(1, static_cast<int>(std::ceil(len / (0.5 * map.resolution))));
    for (int k = 0; k <= n; ++k) {
      const Near near =
          lookNear(map, to_grid, w.a + (w.b - w.a) * (static_cast<double>(k) / n), options);
      if (!near.known) continue;
      ++s.wall_points_seen;
      if (near.occupied) ++s.wall_points_found;
    }
  }
  s.wall_cells_found =
      s.wall_points_seen ? static_cast<double>(s.wall_points_found) / s.wall_points_seen : 0.0;
  for (int r = 0; r < map.height; ++r)
    for (int c = 0; c < map.width; ++c) {
      if (map.at(c, r) < options.occupied_threshold) continue;
      ++s.occupied_cells;
      const Eigen::Vector2d p = cellCentre(map, c, r);
      const Eigen::Vector2d q = closestOnWalls(p, walls);
      const double d = (q - p).norm();
      if (d <= options.tolerance_m + 0.5 * map.resolution) continue;
      ++s.false_wall_cells;
      if (d > options.doubled_range_m) continue;
      // Beside a wall: drawn twice if the wall is also drawn where it is, else drawn once, off.
      if (lookNear(map, to_grid, q, options).occupied)
        ++s.doubled_wall_cells;
      else
        ++s.displaced_wall_cells;
    }
  return s;
}

std::vector<WallSegment> readWalls(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot read the walls file");
  std::vector<WallSegment> walls;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    std::istringstream s(line);
    WallSegment w;
    std::string extra;
    if (!(s >> w.a.x() >> w.a.y() >> w.b.x() >> w.b.y()) || (s >> extra))
      throw std::runtime_error(path + ":" + std::to_string(number) +
                               ": expected 'x0 y0 x1 y1' [m], got '" + line + "'");
    if (!w.a.allFinite() || !w.b.allFinite())
      throw std::runtime_error(path + ":" + std::to_string(number) + ": not finite: '" + line +
                               "'");
    walls.push_back(w);
  }
  return walls;
}

}  // namespace tessera::evaluation
