// Localisation by a calibrated environment camera (docs/algorithms.md#camera-network-calibration).
//
// localizeMarker: the marker's floor position in the calibration's frame (the submap the camera
// was calibrated in) from one detection, with its covariance: the pixel noise (isotropic,
// pixel_std per axis) through the inverse homography plus the calibration's own uncertainty
// (FloorHomography::covariance), both to first order.
//
// localizeMarkerPose: the marker's full pose from its four corners (ArUco order: 0 front-left,
// 1 front-right, 2 rear-right, 3 rear-left, the marker image's top edge facing the robot's
// forward direction, as the simulator renders it): position = the centre of the four corners'
// floor points (a square's centre), heading = direction from the rear edge's midpoint to the
// front edge's. Covariance over (x, y, θ) from the corners' pixel noise and the calibration's
// uncertainty, to first order. The robot's pose is this ⊕ (−marker offset).
//
// fitMapTransform: the rigid transform between two frames from the same marker positions seen in
// both, weighted by their covariances: T = pose of the child frame in the parent frame, with
// parent point ≈ T · child point. With the camera's points as the child (a submap j) and the
// SLAM's as the parent (the current submap i), T is the revisit constraint between the two maps:
// the pose of j's origin in i's frame. The heading comes from the motion during the sighting, so
// a track that does not move (extent below min_extent_m) is refused.
//
// mapTransformFromPoses: the same transform from one robot pose known in both frames
// (docs/algorithms.md#camera-network-calibration gives the formula; this is robot_in_parent ⊕
// robot_in_child⁻¹).
#pragma once

#include <tessera/camera_network/floor_homography.hpp>
#include <tessera/config/config_check.hpp>
#include <tessera/geometry/pose2.hpp>

#include <Eigen/Core>

#include <array>
#include <optional>
#include <string>
#include <vector>

namespace tessera::camera_network {

struct MarkerFix {
  Eigen::Vector2d position = Eigen::Vector2d::Zero();    ///< [m] in the calibration's frame
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();  ///< [m²]
};

/// Nullopt when the pixel's ray misses the floor or the inputs are not finite.
std::optional<MarkerFix> localizeMarker(const FloorHomography& calibration,
                                        const Eigen::Vector2d& pixel, double pixel_std);

struct MarkerPoseFix {
  Pose2 pose;  ///< marker frame in the calibration's frame: centre [m], forward heading [rad]
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  ///< over (x, y, θ)
};

/// Nullopt when a corner's ray misses the floor, the inputs are not finite, or the corners do
/// not form a marker of positive size on the floor.
std::optional<MarkerPoseFix> localizeMarkerPose(const FloorHomography& calibration,
                                                const std::array<Eigen::Vector2d, 4>& corners,
                                                double pixel_std);

/// One marker position seen in both frames.
struct PointCorrespondence {
  Eigen::Vector2d parent = Eigen::Vector2d::Zero();  ///< [m] in the parent frame
  Eigen::Matrix2d parent_covariance = Eigen::Matrix2d::Zero();
  Eigen::Vector2d child = Eigen::Vector2d::Zero();  ///< [m] in the child frame
  Eigen::Matrix2d child_covariance = Eigen::Matrix2d::Zero();
};

struct MapTransformOptions {
  int min_points = 10;        ///< fewer correspondences are refused
  double min_extent_m = 0.5;  ///< refuse tracks shorter than this (largest point distance) [m]
  double max_rms_m = 0.15;    ///< refuse fits whose point RMS exceeds this [m]
  /// Floor on each point's position std in both frames [m] (keeps the weights sane when a
  /// source claims no uncertainty).
  double min_point_std_m = 0.005;

  template <class V>
  void visit(V& v) {
    v("min_points", min_points, "refuse a revisit from fewer sightings");
    v("min_extent_m", min_extent_m,
      "refuse a revisit whose sightings span less than this (no heading without motion) [m]");
    v("max_rms_m", max_rms_m,
      "refuse a revisit whose camera and SLAM positions disagree by more (RMS) [m]");
    v("min_point_std_m", min_point_std_m, "floor on each position's std in the fit [m]");
  }
  ConfigCheck check() const;
};

struct MapTransformFit {
  Pose2 transform;                                       ///< child frame's pose in the parent
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  ///< (x, y, θ) in the parent frame
  double rms_m = 0;                                      ///< point residual RMS after the fit
  double extent_m = 0;                                   ///< largest distance between points
  int points = 0;
};

struct MapTransformResult {
  std::optional<MapTransformFit> fit;
  std::string refusal;
  MapTransformFit measured;  ///< what was measured, also when refused (transform may be unset)
};

/// The rigid motion T with parent_k ≈ T child_k in the least-squares sense, unweighted, in
/// closed form (2D Procrustes); the same number of finite points on both sides, at least one.
/// Points that all coincide give no rotation (0).
Pose2 closedFormRigidFit(const std::vector<Eigen::Vector2d>& child,
                         const std::vector<Eigen::Vector2d>& parent);

/// Non-finite correspondences are dropped first. Throws std::invalid_argument for bad options.
MapTransformResult fitMapTransform(const std::vector<PointCorrespondence>& points,
                                   const MapTransformOptions& options);

/// The pose of the child frame in the parent frame from one robot pose known in both.
inline Pose2 mapTransformFromPoses(const Pose2& robot_in_parent, const Pose2& robot_in_child) {
  return robot_in_parent * robot_in_child.inverse();
}

}  // namespace tessera::camera_network
