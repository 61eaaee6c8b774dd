#include <tessera/sim/world.hpp>

#include <tessera/io/image_file.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace tessera::sim {

namespace {

void requirePositiveResolution(double resolution, const char* what) {
  if (!(resolution > 0) || !std::isfinite(resolution)) {
    std::ostringstream s;
    s << what << ": resolution must be a positive number of metres per cell, got " << resolution;
    throw std::invalid_argument(s.str());
  }
}

// Walls of the built-in office are 0.2 m thick. Every coordinate below is a multiple of 0.05 m
// while cell centres sit at odd multiples of 0.025 m, so no shape edge ever lands on a centre
// and the rasterisation does not depend on rounding.
constexpr double kWall = 0.2;
constexpr double kDoor = 1.2;

void hWall(World& w, double y, double x0, double x1) {
  w.fillRect(x0 - kWall / 2, y - kWall / 2, x1 + kWall / 2, y + kWall / 2);
}
void vWall(World& w, double x, double y0, double y1) {
  w.fillRect(x - kWall / 2, y0 - kWall / 2, x + kWall / 2, y1 + kWall / 2);
}
// A door is carved out after the walls, so it also cuts through wall junctions it overlaps.
void hDoor(World& w, double y, double x_centre, double width = kDoor) {
  w.fillRect(x_centre - width / 2, y - kWall, x_centre + width / 2, y + kWall, false);
}
void vDoor(World& w, double x, double y_centre, double width = kDoor) {
  w.fillRect(x - kWall, y_centre - width / 2, x + kWall, y_centre + width / 2, false);
}

}  // namespace

World::World(int width, int height, double resolution)
    : width_(width), height_(height), resolution_(resolution) {
  if (width <= 0 || height <= 0) {
    std::ostringstream s;
    s << "World: size must be positive, got " << width << " x " << height << " cells";
    throw std::invalid_argument(s.str());
  }
  requirePositiveResolution(resolution, "World");
  cells_.assign(static_cast<std::size_t>(width) * height, 0);
}

World World::fromImage(const std::string& path, double resolution) {
  requirePositiveResolution(resolution, ("world image '" + path + "'").c_str());
  std::error_code ec;
  if (!std::filesystem::exists(path, ec))
    throw std::runtime_error("world image '" + path + "': file not found");
  if (std::filesystem::is_directory(path, ec))
    throw std::runtime_error("world image '" + path + "': is a directory, not an image file");
  if (std::filesystem::file_size(path, ec) == 0)
    throw std::runtime_error("world image '" + path + "': file is empty");
  io::Gray8 img;
  try {
    img = io::readGray8(path);
  } catch (const io::ImageFileError& e) {
    throw std::runtime_error("world image '" + path +
                             "': not a readable image (expected PGM or PNG): " + e.what());
  }
  World w(img.width, img.height, resolution);
  for (int r = 0; r < img.height; ++r) {
    const auto* px = img.pixels.data() + static_cast<std::size_t>(r) * img.width;
    const int row = img.height - 1 - r;  // image row 0 is the top, world row 0 the bottom
    for (int c = 0; c < img.width; ++c) w.setWall(c, row, px[c] < 128);
  }
  w.setName(path);
  return w;
}

void World::saveImage(const std::string& path) const {
  io::Gray8 img;
  img.width = width_;
  img.height = height_;
  img.pixels.resize(static_cast<std::size_t>(width_) * height_);
  for (int r = 0; r < height_; ++r) {
    auto* px = img.pixels.data() + static_cast<std::size_t>(r) * width_;
    const int row = height_ - 1 - r;
    for (int c = 0; c < width_; ++c) px[c] = wall(c, row) ? 0 : 255;
  }
  const std::string ext = std::filesystem::path(path).extension().string();
  try {
    if (ext == ".pgm" || ext == ".PGM")
      io::writePgmFile(img, path);
    else
      io::writePngGray8(img, path);
  } catch (const io::ImageFileError& e) {
    throw std::runtime_error(std::string("cannot write world image: ") + e.what());
  }
}

World World::box(double width_m, double height_m, double resolution, int wall_cells) {
  requirePositiveResolution(resolution, "World::box");
  const int w = static_cast<int>(std::lround(width_m / resolution));
  const int h = static_cast<int>(std::lround(height_m / resolution));
  if (wall_cells < 1 || 2 * wall_cells >= std::min(w, h))
    throw std::invalid_argument("World::box: the walls leave no free space inside");
  World world(w, h, resolution);
  for (int row = 0; row < h; ++row)
    for (int col = 0; col < w; ++col) {
      const bool border =
          col < wall_cells || row < wall_cells || col >= w - wall_cells || row >= h - wall_cells;
      world.setWall(col, row, border);
    }
  world.setName("box");
  return world;
}

World World::builtinOffice() {
  World w(800, 600, 0.05);  // 40 m x 30 m
  w.setName("builtin:office");

  // Outer walls.
  w.fillRect(0, 0, 40, kWall);
  w.fillRect(0, 30 - kWall, 40, 30);
  w.fillRect(0, 0, kWall, 30);
  w.fillRect(40 - kWall, 0, 40, 30);

  // Perimeter room bands (6 m deep) around a 3 m ring corridor; the corridor surrounds a core
  // block x in [9, 31], y in [9, 21].
  hWall(w, 6, 0, 40);
  hWall(w, 24, 0, 40);
  vWall(w, 6, 0, 30);
  vWall(w, 34, 0, 30);
  for (double x : {16.0, 26.0}) {
    vWall(w, x, 0, 6);
    vWall(w, x, 24, 30);
  }
  hWall(w, 15, 0, 6);
  hWall(w, 15, 34, 40);

  // Core outline, cut by an east-west cross corridor (y in [13.5, 16.5]) that is open at both
  // ends: the two corridors form a figure eight, so routes can close loops of different sizes.
  hWall(w, 9, 9, 31);
  hWall(w, 21, 9, 31);
  vWall(w, 9, 9, 21);
  vWall(w, 31, 9, 21);
  hWall(w, 13.5, 9, 31);
  hWall(w, 16.5, 9, 31);
  vWall(w, 20, 9, 13.5);
  vWall(w, 20, 16.5, 21);
  w.fillRect(9 - kWall, 13.6, 9 + kWall, 16.4, false);
  w.fillRect(31 - kWall, 13.6, 31 + kWall, 16.4, false);

  // Doors from rooms to corridors, and from the corner rooms to their neighbours.
  for (double x : {11.0, 21.0, 30.0}) {
    hDoor(w, 6, x);
    hDoor(w, 24, x);
  }
  for (double y : {10.5, 19.5}) {
    vDoor(w, 6, y);
    vDoor(w, 34, y);
  }
  vDoor(w, 6, 3);
  vDoor(w, 34, 3);
  vDoor(w, 6, 27);
  vDoor(w, 34, 27);
  hDoor(w, 13.5, 14.6);
  hDoor(w, 13.5, 25.5);
  hDoor(w, 16.5, 14.5);
  hDoor(w, 16.5, 25.5);
  hDoor(w, 21, 28);
  hDoor(w, 9, 12);

  // Structural pillars standing 1 m off the corridor centre lines: they break up the long
  // featureless corridors the way real columns do, without narrowing the route.
  for (auto [x, y] :
       {std::pair{15.0, 8.5}, {27.0, 6.5}, {33.5, 18.0}, {18.0, 21.5}, {6.5, 12.0}, {23.0, 16.0}})
    w.fillDisc(x, y, 0.2);

  // Furniture: desks and cabinets (boxes) and round tables (discs).
  const double boxes[][4] = {
      {16.6, 4.6, 18.0, 5.6},   {24.2, 0.6, 25.4, 1.4},   {34.6, 6.6, 35.8, 7.6},
      {35.0, 13.2, 36.5, 14.4}, {6.6, 24.6, 8.0, 25.6},   {14.0, 24.6, 15.4, 26.0},
      {9.6, 12.2, 10.8, 13.0},  {18.4, 12.0, 19.4, 13.0}, {22.0, 10.0, 24.0, 11.5},
      {16.0, 18.5, 18.0, 20.0}, {22.0, 18.0, 23.0, 20.0}, {1.0, 8.0, 2.5, 10.0},
      {37.0, 20.0, 39.0, 22.0}, {8.0, 1.0, 10.0, 2.5},    {31.0, 1.0, 33.0, 2.0},
      {27.0, 26.0, 29.0, 27.0}, {2.0, 2.0, 3.0, 4.0},     {36.5, 26.5, 38.0, 28.0}};
  for (const auto& b : boxes) w.fillRect(b[0], b[1], b[2], b[3]);
  const double discs[][3] = {{23.5, 5.0, 0.3},  {39.2, 14.3, 0.25}, {15.2, 29.0, 0.3},
                             {13.0, 9.6, 0.25}, {12.0, 19.0, 0.4},  {3.0, 20.0, 0.4},
                             {21.0, 27.5, 0.5}, {3.0, 27.0, 0.35},  {37.0, 3.0, 0.4}};
  for (const auto& d : discs) w.fillDisc(d[0], d[1], d[2]);

  // 3D-only furniture (furniture.hpp) near the route through the rooms: tables whose tops
  // (0.75 m) the planar laser passes under, chairs and a shelf, for the RGB-D camera.
  w.addFurniture(makeTable(18.6, 4.6, 20.0, 5.6));
  w.addFurniture(makeChair(19.3, 4.1, 3));
  w.addFurniture(makeTable(35.2, 11.4, 36.6, 12.2));
  w.addFurniture(makeChair(36.9, 11.8, 0));
  w.addFurniture(makeTable(8.6, 24.7, 10.0, 25.5));
  w.addFurniture(makeChair(9.3, 26.0, 1));
  w.addFurniture(makeShelf(16.15, 1.0, 16.55, 2.4, 1.8, 4, 2));
  w.addFurniture(makeShelf(39.35, 9.0, 39.75, 10.4, 1.8, 4, 0));

  // Default route, counter-clockwise: the bottom corridor with a detour through the middle
  // bottom room, the east corridor with a detour into the lower east room, the top corridor with
  // the north-west room, down the west corridor, east through the cross corridor with the
  // south-west core room, and back along the east and bottom corridors to the start. The last leg
  // revisits corridors seen at the beginning, so a SLAM run has loops to close. ~206 m.
  w.setDefaultRoute({
      {7.5, 7.5},   {21.0, 7.5},  {21.0, 4.0},  {24.0, 2.5},  {18.0, 2.5},  {21.0, 4.0},
      {21.0, 7.5},  {32.5, 7.5},  {32.5, 10.5}, {37.0, 10.5}, {38.5, 8.5},  {38.5, 12.5},
      {37.0, 10.5}, {32.5, 10.5}, {32.5, 22.5}, {11.0, 22.5}, {11.0, 26.5}, {13.5, 28.0},
      {8.5, 28.0},  {11.0, 26.5}, {11.0, 22.5}, {7.5, 22.5},  {7.5, 15.0},  {14.6, 15.0},
      {14.6, 11.5}, {17.5, 10.5}, {11.5, 10.5}, {14.6, 11.5}, {14.6, 15.0}, {32.5, 15.0},
      {32.5, 7.5},  {7.5, 7.5},
  });
  return w;
}

std::vector<std::string> World::builtinNames() {
  return {"office", "camera_floor", "room", "landmarks"};
}

World World::builtin(std::string_view name) {
  if (name == "office") return builtinOffice();
  if (name == "camera_floor") return builtinCameraFloor();
  if (name == "room") return builtinRoom();
  if (name == "landmarks") return builtinLandmarks();
  std::string known;
  for (const auto& n : builtinNames()) known += (known.empty() ? "" : ", ") + n;
  throw std::runtime_error("unknown built-in world '" + std::string(name) + "' (known: " + known +
                           ")");
}

World World::fromSpec(const std::string& spec, double resolution) {
  constexpr std::string_view kBuiltin = "builtin:";
  if (spec.starts_with(kBuiltin)) return builtin(std::string_view(spec).substr(kBuiltin.size()));
  return fromImage(spec, resolution);
}

void World::setWall(int col, int row, bool is_wall) {
  if (!inside(col, row)) return;
  cells_[static_cast<std::size_t>(row) * width_ + col] = is_wall ? 1 : 0;
}

Eigen::Vector2i World::cellOf(const Eigen::Vector2d& p) const {
  return {static_cast<int>(std::floor(p.x() / resolution_)),
          static_cast<int>(std::floor(p.y() / resolution_))};
}

bool World::blocked(const Eigen::Vector2d& p) const {
  const Eigen::Vector2i c = cellOf(p);
  return !inside(c.x(), c.y()) || wall(c.x(), c.y());
}

double World::clearance(const Eigen::Vector2d& p, double max_distance) const {
  if (blocked(p)) return 0.0;
  double best =
      std::min({max_distance, p.x(), p.y(), widthMeters() - p.x(), heightMeters() - p.y()});
  const Eigen::Vector2i c = cellOf(p);
  const int reach = static_cast<int>(std::ceil(best / resolution_));
  for (int row = std::max(0, c.y() - reach); row <= std::min(height_ - 1, c.y() + reach); ++row)
    for (int col = std::max(0, c.x() - reach); col <= std::min(width_ - 1, c.x() + reach); ++col) {
      if (!wall(col, row)) continue;
      // Distance to the cell's square: clamp p into the square and measure to that point.
      const double qx = std::clamp(p.x(), col * resolution_, (col + 1) * resolution_);
      const double qy = std::clamp(p.y(), row * resolution_, (row + 1) * resolution_);
      best = std::min(best, std::hypot(p.x() - qx, p.y() - qy));
    }
  return best;
}

void World::fillRect(double x0, double y0, double x1, double y1, bool is_wall) {
  if (x1 < x0) std::swap(x0, x1);
  if (y1 < y0) std::swap(y0, y1);
  // Cells whose centre (i + 0.5) * res lies in [x0, x1).
  const int c0 = std::max(0, static_cast<int>(std::ceil(x0 / resolution_ - 0.5)));
  const int c1 = std::min(width_ - 1, static_cast<int>(std::ceil(x1 / resolution_ - 0.5)) - 1);
  const int r0 = std::max(0, static_cast<int>(std::ceil(y0 / resolution_ - 0.5)));
  const int r1 = std::min(height_ - 1, static_cast<int>(std::ceil(y1 / resolution_ - 0.5)) - 1);
  for (int row = r0; row <= r1; ++row)
    for (int col = c0; col <= c1; ++col) setWall(col, row, is_wall);
}

void World::fillDisc(double cx, double cy, double radius, bool is_wall) {
  const int c0 = std::max(0, static_cast<int>(std::floor((cx - radius) / resolution_)));
  const int c1 = std::min(width_ - 1, static_cast<int>(std::floor((cx + radius) / resolution_)));
  const int r0 = std::max(0, static_cast<int>(std::floor((cy - radius) / resolution_)));
  const int r1 = std::min(height_ - 1, static_cast<int>(std::floor((cy + radius) / resolution_)));
  for (int row = r0; row <= r1; ++row)
    for (int col = c0; col <= c1; ++col) {
      const double dx = (col + 0.5) * resolution_ - cx, dy = (row + 0.5) * resolution_ - cy;
      if (dx * dx + dy * dy <= radius * radius) setWall(col, row, is_wall);
    }
}

double routeLength(const Route& route) {
  double length = 0;
  for (std::size_t i = 1; i < route.size(); ++i) length += (route[i] - route[i - 1]).norm();
  return length;
}

double segmentClearance(const World& world, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                        double step, double max_distance) {
  if (!(step > 0)) throw std::invalid_argument("segmentClearance: step must be positive");
  const double length = (b - a).norm();
  const int n = std::max(1, static_cast<int>(std::ceil(length / step)));
  double best = max_distance;
  for (int i = 0; i <= n; ++i)
    best = std::min(best, world.clearance(a + (b - a) * (static_cast<double>(i) / n), best));
  return best;
}

void checkRoute(const World& world, const Route& route, bool closed) {
  auto at = [](const Eigen::Vector2d& p) {
    std::ostringstream s;
    s << "(" << p.x() << ", " << p.y() << ")";
    return s.str();
  };
  if (route.size() < 2)
    throw std::invalid_argument("route needs at least two waypoints, got " +
                                std::to_string(route.size()));
  for (std::size_t i = 0; i < route.size(); ++i) {
    const Eigen::Vector2d& p = route[i];
    if (!std::isfinite(p.x()) || !std::isfinite(p.y()))
      throw std::invalid_argument("route waypoint " + std::to_string(i) + " is not finite");
    const Eigen::Vector2i c = world.cellOf(p);
    if (!world.inside(c.x(), c.y())) {
      std::ostringstream s;
      s << "route waypoint " << i << " at " << at(p) << " is outside world '" << world.name()
        << "' (" << world.widthMeters() << " m x " << world.heightMeters() << " m)";
      throw std::invalid_argument(s.str());
    }
    if (world.wall(c.x(), c.y()))
      throw std::invalid_argument("route waypoint " + std::to_string(i) + " at " + at(p) +
                                  " is inside a wall of world '" + world.name() + "'");
  }
  const std::size_t legs = closed ? route.size() : route.size() - 1;
  for (std::size_t i = 0; i < legs; ++i) {
    const std::size_t j = (i + 1) % route.size();
    const Eigen::Vector2d a = route[i], b = route[j];
    const int n =
        std::max(1, static_cast<int>(std::ceil((b - a).norm() / (0.25 * world.resolution()))));
    for (int k = 1; k < n; ++k) {
      const Eigen::Vector2d p = a + (b - a) * (static_cast<double>(k) / n);
      if (world.blocked(p))
        throw std::invalid_argument("route leg from waypoint " + std::to_string(i) + " " + at(a) +
                                    " to waypoint " + std::to_string(j) + " " + at(b) +
                                    " crosses a wall near " + at(p));
    }
  }
}

}  // namespace tessera::sim
