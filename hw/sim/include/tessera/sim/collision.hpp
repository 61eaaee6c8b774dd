// Collisions of the robot's body with the true 3D world, and the true obstacle map it implies.
//
// The body is a vertical cylinder of `radius` standing on the floor up to `height`
// (FootprintOptions). What it can touch: the wall cells of the World's bitmap (full-height
// structure), the map border (outside the map a robot cannot be), and every furniture box
// (furniture.hpp) whose bottom lies below the body's top, lo.z < height. A table top at 0.71..0.75
// m is thus an obstacle to a 1 m tall robot and not to a 0.5 m tall one, which only meets the legs.
// The planar laser sees none of the furniture, so a navigation stack that trusts its scans alone
// can drive into it: these functions give the simulator's ground truth for that.
//
// Units: metres in the world ("map") frame. Pure functions of the World; no ownership.
#pragma once

#include <tessera/sim/config_check.hpp>
#include <tessera/sim/world.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace tessera::sim {

/// The robot's body for collision checks: a vertical cylinder from the floor up.
struct FootprintOptions {
  double radius = 0.2;  ///< [m]
  double height = 1.0;  ///< [m] furniture whose bottom is at or above this is passed under

  template <class V>
  void visit(V& v) {
    v("radius", radius, "radius of the robot's body, a vertical cylinder [m]");
    v("height", height,
      "height of the body's top above the floor [m]; furniture starting at or above it is "
      "passed under");
  }
  /// Both finite and positive.
  ConfigCheck check() const;
};

/// Planar distance [m] from p to the nearest obstacle a body of `height` can touch: a wall cell
/// (to its closest edge, as World::clearance), the map border, or the xy rectangle of a furniture
/// box with lo.z < height (0 inside one); capped at max_distance. 0 when p is in a wall cell or
/// outside the map. The body of radius r at p touches something when the result is < r.
double footprintClearance(const World& world, const Eigen::Vector2d& p, double height,
                          double max_distance);

/// The true obstacle map for a body of `height`, one value per world cell in the bitmap's
/// geometry (width() x height() cells of resolution(), row-major from row 0 = lowest y, cell
/// (0, 0)'s outer corner at the origin): 100 for a wall cell and for a cell whose square overlaps
/// the xy rectangle of a furniture box with lo.z < height (overlap rather than "centre inside",
/// so a leg thinner than a cell still marks its cell), else 0. The values are those of an
/// msg::OccupancyGrid (0 free, 100 occupied); nothing is unknown.
std::vector<std::int8_t> footprintOccupancy(const World& world, double height);

/// The wall bitmap alone in the same geometry and values (100 wall, 0 free).
std::vector<std::int8_t> wallOccupancy(const World& world);

}  // namespace tessera::sim
