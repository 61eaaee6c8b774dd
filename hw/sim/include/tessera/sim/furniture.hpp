// Furniture of the 3D world: axis-aligned boxes that stand in a World's free space.
//
// The 2D bitmap of a World is its plan of full-height structure (walls, pillars, cabinets): the
// planar laser sees it, and the RGB-D renderer extrudes it from the floor to the ceiling.
// Furniture boxes exist only in 3D (the renderer draws them; the planar laser does not see them),
// which is what a table is to a laser mounted below its top: the beam passes under the top and
// between the legs. Units: metres in the world ("map") frame, z up from the floor.
#pragma once

#include <Eigen/Core>

#include <vector>

namespace tessera::sim {

/// An axis-aligned box [lo, hi] in metres.
struct FurnitureBox {
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
};

/// A table over the footprint [x0, x1] x [y0, y1]: a top slab of `top` metres ending at
/// `height`, on four square legs of side `leg` at the corners.
std::vector<FurnitureBox> makeTable(double x0, double y0, double x1, double y1,
                                    double height = 0.75, double top = 0.04, double leg = 0.05);
/// A chair centred at (cx, cy): a 0.45 m square seat 0.45 m high on four legs, and a back of
/// 0.45 m above the seat on the side given by `back_dir` (0: +x, 1: +y, 2: -x, 3: -y).
std::vector<FurnitureBox> makeChair(double cx, double cy, int back_dir);
/// An open shelf over [x0, x1] x [y0, y1] up to `height`: two side panels, a back panel on the
/// side `back_dir` (as for makeChair) and `boards` evenly spaced boards from 0.1 m up.
std::vector<FurnitureBox> makeShelf(double x0, double y0, double x1, double y1, double height,
                                    int boards, int back_dir);

}  // namespace tessera::sim
