// Collision clearance and obstacle maps of the true 3D world (see collision.hpp).
#include <tessera/sim/collision.hpp>

#include <algorithm>
#include <cmath>

namespace tessera::sim {

namespace {

constexpr std::int8_t kOccupied = 100;

// Whether the body reaches the box: boxes starting at or above its top are passed under.
bool touchable(const FurnitureBox& box, double height) {
  return box.lo.z() < height;
}

}  // namespace

ConfigCheck FootprintOptions::check() const {
  ConfigCheck c;
  c.positive("radius", radius).positive("height", height);
  return c;
}

double footprintClearance(const World& world, const Eigen::Vector2d& p, double height,
                          double max_distance) {
  double best = world.clearance(p, max_distance);
  for (const FurnitureBox& box : world.furniture()) {
    if (!touchable(box, height)) continue;
    // Distance to the rectangle: clamp p into it and measure to that point (0 inside).
    const double qx = std::clamp(p.x(), box.lo.x(), box.hi.x());
    const double qy = std::clamp(p.y(), box.lo.y(), box.hi.y());
    best = std::min(best, std::hypot(p.x() - qx, p.y() - qy));
  }
  return best;
}

std::vector<std::int8_t> wallOccupancy(const World& world) {
  std::vector<std::int8_t> cells(static_cast<std::size_t>(world.width()) * world.height(), 0);
  for (int row = 0; row < world.height(); ++row)
    for (int col = 0; col < world.width(); ++col)
      if (world.wall(col, row))
        cells[static_cast<std::size_t>(row) * world.width() + col] = kOccupied;
  return cells;
}

std::vector<std::int8_t> footprintOccupancy(const World& world, double height) {
  std::vector<std::int8_t> cells = wallOccupancy(world);
  const double res = world.resolution();
  // The cells whose square [i res, (i+1) res) overlaps [lo, hi] with positive area; an edge
  // within a rounding error of a cell boundary counts as on it.
  constexpr double kEps = 1e-9;
  auto first = [&](double lo) { return static_cast<int>(std::floor(lo / res + kEps)); };
  auto last = [&](double hi) { return static_cast<int>(std::ceil(hi / res - kEps)) - 1; };
  for (const FurnitureBox& box : world.furniture()) {
    if (!touchable(box, height)) continue;
    if (!(box.hi.x() > box.lo.x() && box.hi.y() > box.lo.y())) continue;  // no area
    const int c0 = std::max(0, first(box.lo.x())),
              c1 = std::min(world.width() - 1, last(box.hi.x()));
    const int r0 = std::max(0, first(box.lo.y())),
              r1 = std::min(world.height() - 1, last(box.hi.y()));
    for (int row = r0; row <= r1; ++row)
      for (int col = c0; col <= c1; ++col)
        cells[static_cast<std::size_t>(row) * world.width() + col] = kOccupied;
  }
  return cells;
}

}  // namespace tessera::sim
