// Environment camera network (docs/algorithms.md#simulated-motion-and-sensors): fixed ceiling
// cameras looking down at the floor, each reporting a marker on the robot as a pixel position.
//
// Geometry. A camera hangs `ceiling_height` metres above the marker plane (the floor, or the
// height of the marker on the robot; everything here happens in that plane), above its site's
// floor point. Its optical axis points straight down, tilted by small roll (about the image u
// axis) and pitch (about the image v axis) angles; its image u axis points along the site's yaw
// in the world, v to the right of it when seen from above (so the image is not mirrored).
// Pinhole intrinsics: focal length f [px], principal point at the image centre.
//
// The floor -> pixel map of such a camera is the homography H = K R_cw [e1, e2, -C] (C = camera
// centre, z = 0 on the floor): [u v 1]^T ~ H [x y 1]^T with x, y in metres in the world ("map")
// frame. H is scaled so that the site (the floor point below the camera, always in front of it
// for the allowed tilts |roll|, |pitch| < 0.5 rad) maps with third component 1; the third
// component of H [x y 1]^T is then positive exactly for points in front of the camera. For an
// untilted camera that makes H(2,2) = 1 and the last row (0, 0, 1).
//
// Footprint: the floor region whose projection lies in the image ([0, W) x [0, H) pixels) is the
// camera's footprint: the points in front of the camera on the image side of each of the four
// floor lines the image borders map to (H maps lines to lines), a convex region. When every image
// corner's ray meets the floor it is the quadrilateral of the image corners mapped back through
// H^-1 (footprint()); a wide view tilted far enough sees past the horizon, and the region is then
// unbounded (footprintPolygon() clips it).
//
// Observation model (CameraNetwork::observe): for every camera whose footprint contains the
// marker, the marker is missed with probability miss_probability, otherwise reported at its true
// pixel plus isotropic Gaussian noise of pixel_noise px. The network remembers which footprints
// held the marker at the last call and reports enter/leave transitions against it (based on the
// true position, not on detections, so a missed frame does not cause a spurious leave).
//
// Everything is deterministic given the std::mt19937_64 passed in; the number of random draws per
// camera in view is fixed (one uniform, two normals), so outcomes do not shift the stream.
#pragma once

#include <tessera/sim/config_check.hpp>
#include <tessera/sim/world.hpp>

#include <Eigen/Core>

#include <array>
#include <optional>
#include <random>
#include <vector>

namespace tessera::sim {

/// What every camera of a network shares: mounting height, optics and noise.
struct CameraIntrinsics {
  double ceiling_height = 3.0;  ///< camera centre above the marker plane [m]
  double focal_px = 320;        ///< focal length [px]
  int width_px = 640;           ///< image size [px]
  int height_px = 480;
  double pixel_noise = 1.0;        ///< std of the reported pixel, per axis [px]
  double miss_probability = 0.05;  ///< chance a marker in view is not detected in a frame

  template <class V>
  void visit(V& v) {
    v("ceiling_height", ceiling_height, "camera centre above the marker plane [m]");
    v("focal_px", focal_px, "focal length [px]");
    v("width_px", width_px, "image width [px]");
    v("height_px", height_px, "image height [px]");
    v("pixel_noise", pixel_noise, "std of the reported marker pixel per axis [px]");
    v("miss_probability", miss_probability,
      "probability that a marker in view is not detected in a frame");
  }
  /// Finds the first bad field (keys as in visit()).
  ConfigCheck check() const;
  /// Throws std::invalid_argument naming the first bad field.
  void validate() const { check().throwIfBad("camera"); }
};

/// One ceiling camera: its floor -> pixel homography and footprint.
class EnvironmentCamera {
 public:
  /// Throws std::invalid_argument for bad intrinsics or a tilt of 0.5 rad or more.
  EnvironmentCamera(const CameraSite& site, const CameraIntrinsics& intrinsics);

  int id() const { return site_.id; }
  const CameraSite& site() const { return site_; }
  const CameraIntrinsics& intrinsics() const { return intrinsics_; }
  /// Floor (x, y) [m] -> pixel (u, v), scaled so the site maps with third component 1.
  const Eigen::Matrix3d& homography() const { return h_; }

  /// Pixel of a floor point, or nullopt when the point is behind the camera (never for points
  /// near the footprint). The pixel may lie outside the image.
  std::optional<Eigen::Vector2d> project(const Eigen::Vector2d& floor) const;
  /// Floor point of a pixel (inverse homography).
  Eigen::Vector2d floorPoint(const Eigen::Vector2d& pixel) const;
  /// True when the floor point projects inside the image.
  bool inView(const Eigen::Vector2d& floor) const;
  /// The footprint: floor points of the image corners (0,0), (W,0), (W,H), (0,H).
  /// That is the footprint only when every corner's ray meets the floor (footprintPolygon()).
  std::array<Eigen::Vector2d, 4> footprint() const;
  /// The footprint as a convex polygon, counter-clockwise seen from above (x right, y up),
  /// clipped to the square of half-side `max_distance` [m] around the site (which matters only
  /// when the view reaches past the horizon). Equals footprint()'s corners when every corner's ray
  /// meets the floor within that square. Throws std::invalid_argument unless max_distance is
  /// finite and > 0.
  std::vector<Eigen::Vector2d> footprintPolygon(double max_distance) const;

 private:
  CameraSite site_;
  CameraIntrinsics intrinsics_;
  Eigen::Matrix3d h_, h_inv_;
};

/// One camera's report for one frame.
struct MarkerReport {
  int camera_id = 0;
  bool detected = false;
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();       ///< noisy; valid when detected
  Eigen::Vector2d true_pixel = Eigen::Vector2d::Zero();  ///< noise-free
};

/// The marker entered (or left) a camera's footprint since the previous frame.
struct CameraTransition {
  int camera_id = 0;
  bool entered = false;
};

class CameraNetwork {
 public:
  /// Throws std::invalid_argument for duplicate camera ids or bad intrinsics.
  CameraNetwork(const std::vector<CameraSite>& sites, const CameraIntrinsics& intrinsics);

  struct Frame {
    std::vector<CameraTransition> transitions;  ///< leaves first, then entries, by camera order
    std::vector<MarkerReport> reports;          ///< one per camera whose footprint holds the marker
  };
  /// Observes the marker at floor point `marker` [m] from every camera.
  Frame observe(const Eigen::Vector2d& marker, std::mt19937_64& rng);
  /// Forgets which footprints held the marker (the next frame reports fresh entries).
  void reset();

  const std::vector<EnvironmentCamera>& cameras() const { return cameras_; }
  /// Whether camera `index` (not id) held the marker at the last observe().
  bool holding(std::size_t index) const { return inside_.at(index); }

 private:
  std::vector<EnvironmentCamera> cameras_;
  std::vector<bool> inside_;
};

}  // namespace tessera::sim
