// RgbdRenderer: colour and depth images of a pinhole RGB-D camera in the 3D view of a World.
//
// The 3D world: the World's wall cells extruded from the floor (z = 0) to the ceiling
// (z = wall_height), a floor and a ceiling plane, and the World's furniture boxes. Every surface
// carries a deterministic procedural texture (a mosaic of grey-level squares at two scales, tinted
// per wall face, per box face, floor and ceiling) so that a corner detector finds features
// everywhere; faces are shaded by their orientation so edges show too.
//
// Rendering casts one ray per pixel: the floor and ceiling, slab tests against the furniture
// boxes whose projection covers the pixel, and the walls. Walls stand from floor to ceiling, so
// the wall a ray meets depends on its horizontal direction alone, and it can only change where
// that direction passes a corner of the wall outline (as seen from the camera). Each frame sorts
// the corners in front of the camera by direction and finds the wall face of each gap between
// them with one exact grid traversal (as RayCaster, but jumping across open space with a distance
// field); a pixel then looks up its gap and intersects that face's line. The result is the
// traversal's, pixel for pixel, at a fraction of its cost (corridor views cost most: long rays
// that graze walls). Rows run in parallel (TBB).
// Depth is the z coordinate in the camera (not the ray length), with optional noise of std
// depth_noise * z^2 (structured-light cameras' error grows with z squared) and 0 (no reading)
// outside [range_min, range_max]; colour gets optional noise of image_noise grey levels per
// channel. Noise is near-Gaussian (a sum of four uniforms: zero mean, the given std, bounded at
// 3.46 std). The noise of a frame is a function of its noise seed alone, so renders repeat
// exactly whatever the thread count.
//
// Frames: the camera is in the optical convention (x right, y down, z forward); pixel (u, v) with
// depth z is at ((u - cx) z / fx, (v - cy) z / fy, z). The mount is the pose of the camera body
// (x forward, y left, z up; roll about x, then pitch about y (positive = looking down), then yaw
// about z) in base_link, whose origin is on the floor under the robot. Units: metres, radians,
// pixels; colour is 8-bit RGB, row-major, top row first.
//
// Ownership: the renderer keeps a pointer to the World, which must outlive it.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/sim/config_check.hpp>
#include <tessera/sim/world.hpp>

#include <Eigen/Geometry>

#include <tessera/geometry/mount3d.hpp>

#include <cstdint>
#include <span>
#include <vector>

namespace tessera::sim {

/// The pose of a 3D sensor in base_link (see above).
using Mount3D = tessera::Mount3D;

struct RgbdCameraConfig {
  int width = 640, height = 480;                      ///< [px]
  double fx = 525, fy = 525, cx = 319.5, cy = 239.5;  ///< [px]
  double range_min = 0.3;                             ///< [m] nearer depth is no reading (0)
  double range_max = 8.0;       ///< [m] farther depth is no reading (0); colour still shows it
  double depth_noise = 0.0015;  ///< depth std = depth_noise * z^2 [1/m]
  double image_noise = 2.0;     ///< colour noise std [grey levels, 0-255]
  Mount3D mount{0.1, 0.0, 1.0, 0.0, 0.15, 0.0};

  template <class V>
  void visit(V& v) {
    v("width", width, "image width [px]");
    v("height", height, "image height [px]");
    v("fx", fx, "focal length [px]");
    v("fy", fy, "focal length [px]");
    v("cx", cx, "principal point [px]");
    v("cy", cy, "principal point [px]");
    v("range_min", range_min, "[m] nearer depth is no reading (0)");
    v("range_max", range_max, "[m] farther depth is no reading (0)");
    v("depth_noise", depth_noise, "depth noise std = depth_noise * z^2 [1/m]; 0 = none");
    v("image_noise", image_noise, "colour noise std [grey levels]; 0 = none");
    v("mount", mount, "camera pose in base_link (x, y, z [m], roll, pitch, yaw [rad])");
  }
  /// Finds the first bad field (keys as in visit(), the mount's as "mount.z").
  ConfigCheck check() const;
};

/// One rendered frame: rgb has width * height * 3 bytes, depth width * height metres (0 = none).
struct RgbdImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;
  std::vector<float> depth;
};

class RgbdRenderer {
 public:
  /// Throws std::invalid_argument naming the first bad field (of the config, or "wall_height").
  RgbdRenderer(const World& world, double wall_height, const RgbdCameraConfig& config);

  /// The camera's optical frame to the world for a robot at `base` (base_link on the floor).
  Eigen::Isometry3d cameraPose(const Pose2& base) const;

  /// Renders the view of a camera at `camera_to_world` (optical frame); `noise_seed` fixes the
  /// frame's noise. `out` is resized as needed (reuse it across frames to avoid allocations).
  void render(const Eigen::Isometry3d& camera_to_world, std::uint64_t noise_seed,
              RgbdImage& out) const;

  /// Parameter t of the first surface hit at origin + t * dir (dir need not be a unit vector;
  /// with |dir| = 1, t is the distance [m]), or +inf when the ray hits nothing (it leaves the map
  /// horizontally, which only a ray parallel to the floor can).
  double castRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir) const;

  const RgbdCameraConfig& config() const { return config_; }
  double wallHeight() const { return wall_height_; }

 private:
  struct Hit;
  struct Gaps;
  /// The first surface along o + t d among the walls, floor, ceiling and the given boxes.
  Hit trace(const Eigen::Vector3d& o, const Eigen::Vector3d& d, std::span<const int> boxes) const;
  /// The floor, ceiling and the given boxes only.
  Hit traceFloorBoxes(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                      std::span<const int> boxes) const;
  /// Grid traversal of the walls: replaces `hit` by the first wall face nearer than hit.t.
  void traceWalls(const Eigen::Vector3d& o, const Eigen::Vector3d& d, Hit& hit) const;
  /// The wall face of every gap between the corners in front of a camera at `o` (see above).
  void buildGaps(const Eigen::Vector3d& o, const Eigen::Vector2d& forward, Gaps& gaps) const;

  const World* world_;
  double wall_height_;
  RgbdCameraConfig config_;
  /// Per cell: Chebyshev distance in cells to the nearest wall cell, capped at 255 (0 = wall).
  std::vector<std::uint8_t> skip_;
  /// Corners of the wall outline [m]: grid points where the boundary between wall and free cells
  /// (outside the map counts as free) turns or ends.
  std::vector<Eigen::Vector2d> corners_;
};

}  // namespace tessera::sim
