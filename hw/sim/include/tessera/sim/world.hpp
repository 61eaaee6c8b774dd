// World: the simulator's 2D environment, a bitmap of wall cells.
//
// Frame and units: the world frame is the "map" frame. Cell (col, row) covers
// [col*res, (col+1)*res) x [row*res, (row+1)*res) in metres, so the origin (0, 0) is the outer
// lower-left corner of cell (0, 0) and row 0 is the lowest y (images are flipped on load, since
// their row 0 is the top). Everything outside the bitmap is open space: a ray leaving the map hits
// nothing, but a route must stay inside it.
//
// A world may carry a default route (waypoints in metres, in free space) that the simulator
// drives when the profile gives none. The built-in office has one; image worlds do not.
//
// A world may also carry furniture for its 3D view (furniture.hpp): boxes the RGB-D renderer draws
// and the planar laser does not see. The built-in office has tables, chairs and a shelf.
//
// A world may also carry scenario data its built-in scenario needs: ceiling camera sites (the
// seed 000 camera floor), point landmarks (the seed 004 landmark world). wallSegments() derives
// the true straight wall faces from the bitmap (to score line maps against, seed 001 room).
//
// Ownership: a World is a value (copyable); it owns its cells and route.
#pragma once

#include <tessera/sim/furniture.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::sim {

using Route = std::vector<Eigen::Vector2d>;

/// Where a ceiling camera hangs: the floor point below its centre [m], the direction of its
/// image u axis [rad] and small tilts [rad] (see camera_network.hpp).
struct CameraSite {
  int id = 0;
  Eigen::Vector2d position = Eigen::Vector2d::Zero();
  double yaw = 0, roll = 0, pitch = 0;
};

/// A point landmark with its true identity and position [m] in the world frame.
struct PointLandmark {
  int id = 0;
  Eigen::Vector2d position = Eigen::Vector2d::Zero();
};

/// A straight wall face from a to b [m]; free space lies on its left (a -> b counter-clockwise
/// around the wall).
struct WallSegment {
  Eigen::Vector2d a = Eigen::Vector2d::Zero(), b = Eigen::Vector2d::Zero();
  double length() const { return (b - a).norm(); }
};

class World {
 public:
  /// An all-free world of width x height cells of `resolution` metres each.
  /// Throws std::invalid_argument for non-positive sizes or resolution.
  World(int width, int height, double resolution);

  /// Loads a PGM/PNG (any format OpenCV reads): pixels darker than 128 are walls. Throws
  /// std::invalid_argument for a non-positive resolution and std::runtime_error naming the file
  /// when it is missing, not an image, or empty.
  static World fromImage(const std::string& path, double resolution);
  /// An office floor of about 40 m x 30 m at 0.05 m/cell: perimeter rooms, a ring corridor, a
  /// core cut by a cross corridor (two loops), doors, pillars and furniture, with a ~200 m
  /// default route that visits three rooms and returns to its start.
  static World builtinOffice();
  /// Seed 000: an 85 m x 63 m office floor at 0.05 m/cell: rooms along the outside, a ring
  /// corridor and a cross of corridors (four loops), rooms in the four blocks, columns at wall
  /// junctions, 7 ceiling camera sites over corridor crossings, and a ~1.5 km default route
  /// (corridor loops, with a small calibration loop under each camera at its first visit).
  static World builtinCameraFloor();
  /// Seed 001: a 10 m x 8 m structured room (0.2 m walls, a partition, two pillars, a cabinet
  /// and a wall jog; only axis-aligned straight walls: 24 faces, 23 of them at least 0.3 m long)
  /// with a ~15 m loop route.
  static World builtinRoom();
  /// Seed 004: a 100 m x 90 m open area (no walls, 0.5 m/cell) with 27 point landmarks along a
  /// loop of 14 waypoints (the default route).
  static World builtinLandmarks();
  /// A built-in world by name ("office", "camera_floor", "room", "landmarks"); throws
  /// std::runtime_error listing the known names.
  static World builtin(std::string_view name);
  /// The value of a `world` option: "builtin:NAME" or the path of a PGM/PNG image read at
  /// `resolution` m/pixel. Throws std::invalid_argument for a bad resolution, std::runtime_error
  /// for an unknown name or an unreadable image.
  static World fromSpec(const std::string& spec, double resolution);
  static std::vector<std::string> builtinNames();
  /// A closed room: a width_m x height_m map (rounded to whole cells) whose outermost
  /// `wall_cells` rings of cells are walls. Handy for tests with analytic distances.
  static World box(double width_m, double height_m, double resolution, int wall_cells = 1);

  int width() const { return width_; }
  int height() const { return height_; }
  double resolution() const { return resolution_; }
  double widthMeters() const { return width_ * resolution_; }
  double heightMeters() const { return height_ * resolution_; }

  bool inside(int col, int row) const {
    return col >= 0 && row >= 0 && col < width_ && row < height_;
  }
  /// True for a wall cell; cells outside the map are not walls.
  bool wall(int col, int row) const {
    return inside(col, row) && cells_[static_cast<std::size_t>(row) * width_ + col] != 0;
  }
  void setWall(int col, int row, bool is_wall);
  /// The cell containing point p (may be outside the map).
  Eigen::Vector2i cellOf(const Eigen::Vector2d& p) const;
  /// True when p lies in a wall cell or outside the map (where a robot cannot be).
  bool blocked(const Eigen::Vector2d& p) const;

  /// Distance from p to the nearest wall cell (to its closest edge, 0 inside one) or to the map
  /// border, capped at max_distance. Cost grows with (max_distance / resolution)^2.
  double clearance(const Eigen::Vector2d& p, double max_distance) const;

  // Drawing in metres (used to build worlds in code). A cell is set when its centre lies in the
  // shape, so shapes snap to the grid predictably.
  void fillRect(double x0, double y0, double x1, double y1, bool is_wall = true);
  void fillDisc(double cx, double cy, double radius, bool is_wall = true);

  /// Writes the bitmap as an image (walls black, free white; format from the extension, e.g.
  /// .pgm or .png), top row = highest y, so fromImage(saveImage(w)) == w.
  void saveImage(const std::string& path) const;

  const Route& defaultRoute() const { return default_route_; }
  void setDefaultRoute(Route route) { default_route_ = std::move(route); }
  /// Where the world came from ("builtin:office", a file path, "box"), for messages.
  const std::string& name() const { return name_; }
  void setName(std::string name) { name_ = std::move(name); }

  /// Ceiling camera sites (empty unless the scenario has a camera network).
  const std::vector<CameraSite>& cameraSites() const { return camera_sites_; }
  void setCameraSites(std::vector<CameraSite> sites) { camera_sites_ = std::move(sites); }
  /// Point landmarks (empty unless the scenario has them).
  const std::vector<PointLandmark>& landmarks() const { return landmarks_; }
  void setLandmarks(std::vector<PointLandmark> landmarks) { landmarks_ = std::move(landmarks); }

  /// Furniture boxes of the 3D view (empty unless the world has them).
  const std::vector<FurnitureBox>& furniture() const { return furniture_; }
  void addFurniture(const std::vector<FurnitureBox>& boxes) {
    furniture_.insert(furniture_.end(), boxes.begin(), boxes.end());
  }

  friend bool operator==(const World& a, const World& b) {
    return a.width_ == b.width_ && a.height_ == b.height_ && a.resolution_ == b.resolution_ &&
           a.cells_ == b.cells_;
  }

 private:
  int width_ = 0, height_ = 0;
  double resolution_ = 0;
  std::vector<std::uint8_t> cells_;  // row-major from row 0 (lowest y); 1 = wall
  Route default_route_;
  std::string name_;
  std::vector<CameraSite> camera_sites_;
  std::vector<PointLandmark> landmarks_;
  std::vector<FurnitureBox> furniture_;
};

/// The wall faces of the bitmap: every boundary between a wall cell and a free cell inside the
/// map, merged into maximal straight runs (axis-aligned, as the cells are), free space on the
/// left of a -> b. Runs shorter than min_length [m] (the stair steps of round shapes) are dropped.
/// For worlds drawn from axis-aligned rectangles this is exactly the list of straight walls.
std::vector<WallSegment> wallSegments(const World& world, double min_length = 0.0);

/// Total polyline length of a route [m].
double routeLength(const Route& route);

/// Smallest clearance() met along the segment a-b, sampled every `step` metres (both ends
/// included), capped at max_distance.
double segmentClearance(const World& world, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                        double step, double max_distance);

/// Checks that a robot can drive `route` in `world`: at least two waypoints, every waypoint
/// inside the map and off walls, and no leg crossing a wall (sampled every quarter cell). With
/// `closed` the leg from the last waypoint back to the first is checked too (for several laps).
/// Throws std::invalid_argument naming the waypoint index (0-based) and coordinates.
void checkRoute(const World& world, const Route& route, bool closed = false);

}  // namespace tessera::sim
