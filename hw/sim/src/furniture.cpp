// Furniture helpers: tables, chairs and shelves as lists of axis-aligned boxes [m].
#include <tessera/sim/furniture.hpp>

#include <algorithm>

namespace tessera::sim {

namespace {

FurnitureBox box(double x0, double y0, double z0, double x1, double y1, double z1) {
  return {{std::min(x0, x1), std::min(y0, y1), std::min(z0, z1)},
          {std::max(x0, x1), std::max(y0, y1), std::max(z0, z1)}};
}

void addLegs(std::vector<FurnitureBox>& out, double x0, double y0, double x1, double y1,
             double top_z, double leg) {
  for (double x : {x0, x1 - leg})
    for (double y : {y0, y1 - leg}) out.push_back(box(x, y, 0, x + leg, y + leg, top_z));
}

// A thin panel along one side of the footprint: 0 = +x, 1 = +y, 2 = -x, 3 = -y.
FurnitureBox sidePanel(double x0, double y0, double x1, double y1, double z0, double z1,
                       double thick, int side) {
  switch (side & 3) {
    case 0:
      return box(x1 - thick, y0, z0, x1, y1, z1);
    case 1:
      return box(x0, y1 - thick, z0, x1, y1, z1);
    case 2:
      return box(x0, y0, z0, x0 + thick, y1, z1);
    default:
      return box(x0, y0, z0, x1, y0 + thick, z1);
  }
}

}  // namespace

std::vector<FurnitureBox> makeTable(double x0, double y0, double x1, double y1, double height,
                                    double top, double leg) {
  std::vector<FurnitureBox> out;
  out.push_back(box(x0, y0, height - top, x1, y1, height));
  addLegs(out, x0, y0, x1, y1, height - top, leg);
  return out;
}

std::vector<FurnitureBox> makeChair(double cx, double cy, int back_dir) {
  constexpr double kHalf = 0.225, kSeat = 0.45, kSeatThick = 0.04, kBack = 0.45;
  const double x0 = cx - kHalf, y0 = cy - kHalf, x1 = cx + kHalf, y1 = cy + kHalf;
  std::vector<FurnitureBox> out;
  out.push_back(box(x0, y0, kSeat - kSeatThick, x1, y1, kSeat));
  addLegs(out, x0, y0, x1, y1, kSeat - kSeatThick, 0.04);
  out.push_back(sidePanel(x0, y0, x1, y1, kSeat, kSeat + kBack, 0.04, back_dir));
  return out;
}

std::vector<FurnitureBox> makeShelf(double x0, double y0, double x1, double y1, double height,
                                    int boards, int back_dir) {
  constexpr double kThick = 0.03;
  std::vector<FurnitureBox> out;
  // Side panels across the back direction, so the shelf opens away from its back.
  const int side_a = (back_dir + 1) & 3, side_b = (back_dir + 3) & 3;
  out.push_back(sidePanel(x0, y0, x1, y1, 0, height, kThick, side_a));
  out.push_back(sidePanel(x0, y0, x1, y1, 0, height, kThick, side_b));
  out.push_back(sidePanel(x0, y0, x1, y1, 0, height, kThick, back_dir));
  for (int i = 0; i < boards; ++i) {
    const double z = 0.1 + (height - 0.1) * i / std::max(1, boards - 1);
    out.push_back(box(x0, y0, std::min(z, height - kThick), x1, y1, std::min(z + kThick, height)));
  }
  return out;
}

}  // namespace tessera::sim
