// The scenario worlds of the source papers (seeds 000, 001 and 004) and wallSegments().
#include <tessera/sim/world.hpp>

#include <array>
#include <cmath>
#include <utility>

namespace tessera::sim {

namespace {

// As in the office: 0.2 m walls on coordinates that are multiples of 0.05 m, so shape edges
// never fall on cell centres (odd multiples of 0.025 m) and rasterisation is unambiguous.
constexpr double kWall = 0.2;
constexpr double kDoor = 1.2;

void hWall(World& w, double y, double x0, double x1) {
  w.fillRect(x0 - kWall / 2, y - kWall / 2, x1 + kWall / 2, y + kWall / 2);
}
void vWall(World& w, double x, double y0, double y1) {
  w.fillRect(x - kWall / 2, y0 - kWall / 2, x + kWall / 2, y1 + kWall / 2);
}
void hDoor(World& w, double y, double x_centre) {
  w.fillRect(x_centre - kDoor / 2, y - kWall, x_centre + kDoor / 2, y + kWall, false);
}
void vDoor(World& w, double x, double y_centre) {
  w.fillRect(x - kWall, y_centre - kDoor / 2, x + kWall, y_centre + kDoor / 2, false);
}
// Door centres snapped to 0.1 m so their edges stay on the 0.05 m lattice.
double snap(double v) {
  return std::round(v * 10) / 10;
}

}  // namespace

// ---- seed 000: camera floor ----

World World::builtinCameraFloor() {
  World w(1700, 1260, 0.05);  // 85 m x 63 m
  w.setName("builtin:camera_floor");

  // Corridor centre lines (3 m wide corridors, walls at +-1.6 m): a ring and a cross, so the
  // crossings form a 3 x 3 grid of nodes and the corridors four loops.
  constexpr std::array<double, 3> kX = {7.5, 42.5, 77.5};
  constexpr std::array<double, 3> kY = {7.5, 31.5, 55.5};
  constexpr double kHalf = 1.6;

  // Exterior.
  w.fillRect(0, 0, 85, kWall);
  w.fillRect(0, 63 - kWall, 85, 63);
  w.fillRect(0, 0, kWall, 63);
  w.fillRect(85 - kWall, 0, 85, 63);

  // Outer wall of the ring corridor; the band outside it is a row of rooms.
  const double ox0 = kX[0] - kHalf, ox1 = kX[2] + kHalf, oy0 = kY[0] - kHalf, oy1 = kY[2] + kHalf;
  hWall(w, oy0, ox0, ox1);
  hWall(w, oy1, ox0, ox1);
  vWall(w, ox0, oy0, oy1);
  vWall(w, ox1, oy0, oy1);
  // Exterior rooms: cross walls from the exterior to the corridor wall (the outermost ones cut
  // off closed corner rooms).
  const std::array<double, 10> band_x = {6.0, 14.5, 23.0, 31.5, 40.0, 45.0, 53.5, 62.0, 70.5, 79.0};
  const std::array<double, 8> band_y = {6.0, 14.0, 22.0, 29.0, 34.0, 41.0, 49.0, 57.0};
  for (double x : band_x) {
    vWall(w, x, 0, oy0);
    vWall(w, x, oy1, 63);
  }
  for (double y : band_y) {
    hWall(w, y, 0, ox0);
    hWall(w, y, ox1, 85);
  }

  // Four blocks between the corridors, each two rows of four rooms, with columns where the
  // room walls meet the corridor walls (they stand 0.15 m proud of the wall: laser features
  // along otherwise featureless corridors).
  struct Block {
    double x0, x1, y0, y1;
  };
  const Block blocks[] = {{kX[0] + kHalf, kX[1] - kHalf, kY[0] + kHalf, kY[1] - kHalf},
                          {kX[1] + kHalf, kX[2] - kHalf, kY[0] + kHalf, kY[1] - kHalf},
                          {kX[0] + kHalf, kX[1] - kHalf, kY[1] + kHalf, kY[2] - kHalf},
                          {kX[1] + kHalf, kX[2] - kHalf, kY[1] + kHalf, kY[2] - kHalf}};
  std::vector<std::array<double, 2>> columns;
  std::vector<std::array<double, 3>> h_doors;  // y, x
  for (const Block& b : blocks) {
    hWall(w, b.y0, b.x0, b.x1);
    hWall(w, b.y1, b.x0, b.x1);
    vWall(w, b.x0, b.y0, b.y1);
    vWall(w, b.x1, b.y0, b.y1);
    const double ym = 0.5 * (b.y0 + b.y1);
    hWall(w, ym, b.x0, b.x1);
    const double room = (b.x1 - b.x0) / 4;
    for (int k = 1; k < 4; ++k) {
      const double x = b.x0 + k * room;
      vWall(w, x, b.y0, b.y1);
      columns.push_back({x, b.y0});
      columns.push_back({x, b.y1});
    }
    for (int k = 0; k < 4; ++k) {
      const double xc = snap(b.x0 + (k + 0.5) * room);
      h_doors.push_back({b.y0, xc, 0});
      h_doors.push_back({b.y1, xc, 0});
    }
  }
  for (const auto& c : columns) w.fillRect(c[0] - 0.25, c[1] - 0.25, c[0] + 0.25, c[1] + 0.25);
  for (const auto& d : h_doors) hDoor(w, d[0], d[1]);
  // One door from each exterior room onto the ring corridor.
  for (std::size_t i = 0; i + 1 < band_x.size(); ++i) {
    const double xc = snap(0.5 * (band_x[i] + band_x[i + 1]));
    hDoor(w, oy0, xc);
    hDoor(w, oy1, xc);
  }
  for (std::size_t i = 0; i + 1 < band_y.size(); ++i) {
    const double yc = snap(0.5 * (band_y[i] + band_y[i + 1]));
    vDoor(w, ox0, yc);
    vDoor(w, ox1, yc);
  }

  // A few cabinets and tables in the rooms the laser sees through the doors.
  const double boxes[][4] = {{16.0, 1.0, 18.0, 2.0},   {57.0, 1.0, 58.5, 3.0},
                             {11.0, 12.0, 12.5, 13.5}, {47.0, 26.0, 49.0, 27.5},
                             {25.0, 45.0, 27.0, 46.0}, {66.0, 36.0, 67.5, 38.0},
                             {1.0, 40.0, 2.5, 42.0},   {81.0, 20.0, 83.0, 21.5},
                             {33.0, 60.0, 35.0, 61.5}, {72.0, 59.0, 73.5, 61.0}};
  for (const auto& b : boxes) w.fillRect(b[0], b[1], b[2], b[3]);

  // Cameras over 7 of the 9 crossings (not over the middle of the side corridors), each with a
  // small made-up mounting error.
  const std::array<std::array<int, 2>, 7> cam_nodes = {
      {{0, 0}, {1, 0}, {2, 0}, {2, 2}, {1, 2}, {0, 2}, {1, 1}}};
  const double tilts[7][3] = {{0.00, 0.02, -0.01}, {0.30, -0.01, 0.02}, {-0.20, 0.015, 0.0},
                              {1.57, -0.02, 0.01}, {0.10, 0.0, -0.015}, {-1.50, 0.01, 0.01},
                              {0.75, -0.01, -0.02}};
  std::vector<CameraSite> sites;
  for (int i = 0; i < 7; ++i) {
    CameraSite s;
    s.id = i;
    s.position = {kX[cam_nodes[i][0]], kY[cam_nodes[i][1]]};
    s.yaw = tilts[i][0];
    s.roll = tilts[i][1];
    s.pitch = tilts[i][2];
    sites.push_back(s);
  }
  w.setCameraSites(sites);

  // Route over the crossing grid (i, j) -> (kX[i], kY[j]): the outer ring counter-clockwise,
  // the four block loops in several combinations, diagonals of long straight runs, and the ring
  // clockwise, so every corridor is driven in both directions and every camera revisited. At a
  // camera's first visit the robot drives a 1 m diamond around the crossing centre: the curve
  // the camera needs to calibrate. ~1.5 km.
  const int nodes[][2] = {
      {0, 0}, {1, 0}, {2, 0}, {2, 1}, {2, 2}, {1, 2}, {0, 2}, {0, 1}, {0, 0},  // ring, ccw
      {1, 0}, {1, 1}, {0, 1}, {0, 0},                                          // block SW
      {0, 1}, {0, 2}, {1, 2}, {1, 1}, {0, 1},                                  // block NW
      {1, 1}, {2, 1}, {2, 2}, {1, 2}, {1, 1},                                  // block NE
      {1, 0}, {2, 0}, {2, 1}, {1, 1},                                          // block SE
      {1, 2}, {0, 2}, {0, 0}, {2, 0}, {2, 2}, {1, 2}, {1, 0}, {0, 0},          // long runs
      {0, 1}, {0, 2}, {1, 2}, {2, 2}, {2, 1}, {2, 0}, {1, 0},                  // ring, cw
      {1, 1}, {2, 1}, {2, 0}, {1, 0}};
  std::vector<bool> visited(7, false);
  Route route;
  for (const auto& n : nodes) {
    const Eigen::Vector2d p(kX[n[0]], kY[n[1]]);
    if (!route.empty() && (route.back() - p).norm() < 1e-9) continue;
    route.push_back(p);
    for (int i = 0; i < 7; ++i) {
      if (visited[i] || cam_nodes[i][0] != n[0] || cam_nodes[i][1] != n[1]) continue;
      visited[i] = true;
      for (const auto& d : {Eigen::Vector2d(1, 0), Eigen::Vector2d(0, 1), Eigen::Vector2d(-1, 0),
                            Eigen::Vector2d(0, -1), Eigen::Vector2d(1, 0)})
        route.push_back(p + d);
      route.push_back(p);
    }
  }
  w.setDefaultRoute(std::move(route));
  return w;
}

// ---- seed 001: structured room ----

World World::builtinRoom() {
  World w(208, 168, 0.05);  // 10.4 m x 8.4 m outside, 10 m x 8 m inside
  w.setName("builtin:room");
  w.fillRect(0, 0, 10.4, kWall);
  w.fillRect(0, 8.4 - kWall, 10.4, 8.4);
  w.fillRect(0, 0, kWall, 8.4);
  w.fillRect(10.4 - kWall, 0, 10.4, 8.4);
  w.fillRect(4.9, 5.2, 5.1, 8.2);   // partition hanging from the north wall
  w.fillRect(2.7, 3.7, 3.3, 4.3);   // square pillar, 0.6 m
  w.fillRect(7.0, 5.5, 7.5, 6.0);   // second pillar, 0.5 m
  w.fillRect(6.5, 0.2, 8.0, 0.8);   // cabinet against the south wall
  w.fillRect(9.6, 3.0, 10.2, 5.0);  // jog in the east wall
  // One loop around the square pillar, back to the start: ~15 m.
  w.setDefaultRoute({{1.5, 1.5}, {5.8, 1.5}, {5.8, 4.8}, {1.5, 4.8}, {1.5, 1.5}});
  return w;
}

// ---- seed 004: landmark world ----

World World::builtinLandmarks() {
  World w(200, 180, 0.5);  // 100 m x 90 m, no walls
  w.setName("builtin:landmarks");
  // A loop of 14 waypoints around the area, counter-clockwise, ending 11 m from its start.
  w.setDefaultRoute({{10, 10},
                     {35, 8},
                     {60, 12},
                     {85, 10},
                     {92, 30},
                     {80, 48},
                     {90, 68},
                     {75, 82},
                     {50, 78},
                     {30, 84},
                     {10, 75},
                     {20, 55},
                     {8, 38},
                     {15, 20}});
  // 27 landmarks scattered 3 - 20 m either side of the loop.
  const double lm[27][2] = {{15, 3},  {25, 16}, {40, 2},  {48, 18}, {65, 4},  {72, 19}, {90, 3},
                            {98, 22}, {84, 35}, {97, 45}, {72, 55}, {96, 60}, {85, 88}, {68, 72},
                            {58, 87}, {42, 72}, {38, 88}, {20, 88}, {3, 82},  {18, 68}, {28, 60},
                            {2, 55},  {18, 44}, {25, 35}, {3, 28},  {45, 30}, {55, 62}};
  std::vector<PointLandmark> landmarks;
  for (int i = 0; i < 27; ++i) landmarks.push_back({i, {lm[i][0], lm[i][1]}});
  w.setLandmarks(std::move(landmarks));
  return w;
}

// ---- wall faces ----

std::vector<WallSegment> wallSegments(const World& world, double min_length) {
  const double res = world.resolution();
  std::vector<WallSegment> out;
  auto emit = [&](Eigen::Vector2d a, Eigen::Vector2d b) {
    if ((b - a).norm() + 1e-9 >= min_length) out.push_back({a, b});
  };
  auto freeCell = [&](int c, int r) { return world.inside(c, r) && !world.wall(c, r); };
  // Horizontal faces: on the line y = r * res between rows r-1 and r. Wall below, free above:
  // free on the left when walking +x. Wall above, free below: walk -x.
  for (int r = 0; r <= world.height(); ++r) {
    for (int dir : {+1, -1}) {
      int start = -1;
      for (int c = 0; c <= world.width(); ++c) {
        bool face = false;
        if (c < world.width()) {
          face = dir > 0 ? (world.wall(c, r - 1) && freeCell(c, r))
                         : (world.wall(c, r) && freeCell(c, r - 1));
        }
        if (face && start < 0) start = c;
        if (!face && start >= 0) {
          const Eigen::Vector2d lo(start * res, r * res), hi(c * res, r * res);
          dir > 0 ? emit(lo, hi) : emit(hi, lo);
          start = -1;
        }
      }
    }
  }
  // Vertical faces: on x = c * res. Wall left, free right: walk -y; wall right, free left: +y.
  for (int c = 0; c <= world.width(); ++c) {
    for (int dir : {+1, -1}) {
      int start = -1;
      for (int r = 0; r <= world.height(); ++r) {
        bool face = false;
        if (r < world.height()) {
          face = dir > 0 ? (world.wall(c, r) && freeCell(c - 1, r))
                         : (world.wall(c - 1, r) && freeCell(c, r));
        }
        if (face && start < 0) start = r;
        if (!face && start >= 0) {
          const Eigen::Vector2d lo(c * res, start * res), hi(c * res, r * res);
          dir > 0 ? emit(lo, hi) : emit(hi, lo);
          start = -1;
        }
      }
    }
  }
  return out;
}

}  // namespace tessera::sim
