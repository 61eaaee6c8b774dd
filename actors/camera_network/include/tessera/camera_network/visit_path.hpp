// Visit path refinement: a calibration visit's path corrected with the camera's own pixels
// (docs/algorithms.md#camera-network-calibration).
//
// A calibration visit's path is the odometry's, rigidly placed on the SLAM's poses
// (CameraConstraintBuilderOptions::odometry_shape). Its shape is good over tens of seconds, but
// the wheels' random errors still bend it: over the loop the robot drives under a camera, the
// heading wanders by about 0.01 rad and the distance by about a centimetre, which is as much as
// the detector's pixel noise (at 3 m with a 320 px focal length, 1 px is about 1 cm on the floor).
// The camera sees the path too, so the two are estimated together: the floor -> pixel homography
// and, for each `segment_s` seconds of the visit, one heading correction (spread over the
// segment's increments in proportion to their rotation noise) and one distance correction (a
// scale of the segment's translations), each held by the prior the odometry noise model gives it.
// Levenberg-Marquardt minimises the inliers' pixel residuals (over pixel_std) plus the priors.
// The corrected path is then placed rigidly on the SLAM's poses of the visit, since the SLAM, not
// the camera, says where the visit is in its submap; the caller calibrates again on it.
//
// Units: metres, radians, pixels, nanoseconds. Poses: the robot (base_link) in the calibration
// frame, one per pixel, in time order, odometry-shaped (their increments are the odometry's).
// Plain data in, plain data out; deterministic; never throws for bad data (a refusal says why).
#pragma once

#include <tessera/camera_network/floor_homography.hpp>
#include <tessera/config/config_check.hpp>
#include <tessera/geometry/pose2.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace tessera::camera_network {

/// The odometry's random error model: variances that grow with distance and rotation.
struct VisitPathOptions {
  bool enabled = true;
  double segment_s = 2.0;             ///< one heading and one distance correction per segment [s]
  double distance_var_per_m = 2e-5;   ///< distance error variance per metre driven [m²/m]
  double heading_var_per_rad = 2e-5;  ///< heading error variance per radian turned [rad²/rad]
  double heading_var_per_m = 1e-6;    ///< heading error variance per metre driven [rad²/m]
  int max_iterations = 15;            ///< Levenberg-Marquardt iterations

  template <class V>
  void visit(V& v) {
    v("enabled", enabled,
      "refine a calibration visit's odometry path with the camera's pixels before calibrating");
    v("segment_s", segment_s, "one heading and one distance correction per this many seconds");
    v("distance_var_per_m", distance_var_per_m,
      "odometry distance error variance per metre driven [m^2/m]");
    v("heading_var_per_rad", heading_var_per_rad,
      "odometry heading error variance per radian turned [rad^2/rad]");
    v("heading_var_per_m", heading_var_per_m,
      "odometry heading error variance per metre driven [rad^2/m]");
    v("max_iterations", max_iterations, "Levenberg-Marquardt iterations, >= 1");
  }
  ConfigCheck check() const;
};

struct VisitPathResult {
  std::vector<Pose2> poses;  ///< corrected, one per input pose; empty when refused
  std::string refusal;       ///< why not, when refused
  int segments = 0;
  int inliers = 0;           ///< pixels within inlier_px of the initial homography
  double rms_before_px = 0;  ///< inliers' reprojection RMS with the initial homography
  double rms_after_px = 0;   ///< with the corrected path and the jointly refined homography
  double prior_chi2 = 0;     ///< Σ correction² / variance (about 2 × segments if the model fits)
  double max_heading_rad = 0;  ///< largest accumulated heading correction along the path
};

/// Refines the path `poses` (stamps `stamps_ns`, increasing) seen at `pixels` with the marker at
/// `marker` in base_link, starting from `initial` (a homography calibrated on `poses`).
/// Pixels further than `inlier_px` from `initial`'s projection are left out. `pixel_std` [px]
/// > 0. The result is placed by the rigid motion that best fits its positions to those of
/// `anchor` (the SLAM's poses at the same stamps; `poses` themselves when empty). Throws
/// std::invalid_argument for bad options only.
VisitPathResult refineVisitPath(const std::vector<std::int64_t>& stamps_ns,
                                const std::vector<Pose2>& poses, const std::vector<Pose2>& anchor,
                                const std::vector<Eigen::Vector2d>& pixels,
                                const Eigen::Vector2d& marker, const FloorHomography& initial,
                                double pixel_std, double inlier_px,
                                const VisitPathOptions& options);

}  // namespace tessera::camera_network
