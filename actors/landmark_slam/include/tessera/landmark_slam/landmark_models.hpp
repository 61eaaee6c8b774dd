// Models shared by point-landmark filters (docs/algorithms.md#landmark-slam): the range-bearing
// sensor, its inverse (landmark initialisation), the car-like / differential-drive motion step,
// each with Jacobians, Mahalanobis gating and chi-square thresholds. Header + small .cpp, no
// allocation.
//
// Frames and units: robot pose x = (x, y, theta) of base_link in the map frame [m, m, rad];
// landmark m = (x, y) in the map frame [m]; the sensor is mounted at `mount` in base_link.
// Observation z = (range [m], bearing [rad]) from the sensor, bearing counter-clockwise from the
// sensor's x axis, wrapped to (-pi, pi]:
//   s = pose ⊕ mount,  z = [ |m - s_xy|,  atan2(m_y - s_y, m_x - s_x) - s_theta ].
// Motion (one explicit Euler step of length dt, as hw/sim/car_like.hpp):
//   car-like (wheelbase L > 0): x += dt V cos(theta + gamma), y += dt V sin(theta + gamma),
//                               theta += dt V sin(gamma) / L;  u = (V, gamma)
//   differential drive (L = 0): x += dt V cos(theta), y += dt V sin(theta), theta += dt omega;
//                               u = (V, omega)
#pragma once

#include <tessera/geometry/pose2.hpp>

#include <Eigen/Core>

namespace tessera::landmark_slam {

/// Predicted observation of landmark m from the sensor at pose ⊕ mount, with the Jacobians with
/// respect to the pose (2x3) and the landmark (2x2). Not defined for a landmark at the sensor.
struct RangeBearingPrediction {
  Eigen::Vector2d z;
  Eigen::Matrix<double, 2, 3> H_pose;
  Eigen::Matrix2d H_landmark;
};
RangeBearingPrediction predictRangeBearing(const Eigen::Vector3d& pose, const Eigen::Vector2d& m,
                                           const Pose2& mount = {});

/// Landmark position from a range-bearing observation z taken at pose ⊕ mount, with the
/// Jacobians with respect to the pose (2x3) and the observation (2x2).
struct LandmarkFromObservation {
  Eigen::Vector2d m;
  Eigen::Matrix<double, 2, 3> G_pose;
  Eigen::Matrix2d G_z;
};
LandmarkFromObservation landmarkFromRangeBearing(const Eigen::Vector3d& pose,
                                                 const Eigen::Vector2d& z, const Pose2& mount = {});

/// A drive control held for dt seconds; see the header comment for the two models.
struct DriveInput {
  double speed = 0;      ///< V [m/s]
  double steer = 0;      ///< gamma [rad] (car-like) ...
  double turn_rate = 0;  ///< ... or omega [rad/s] (differential drive)
  double wheelbase = 0;  ///< L [m]; 0 selects the differential drive
  double dt = 0;         ///< [s]
  bool carLike() const { return wheelbase > 0; }
};

/// One motion step with the Jacobians with respect to the pose (3x3) and the control (3x2,
/// columns: speed and steering angle or turn rate). theta of the result is wrapped.
struct MotionStep {
  Eigen::Vector3d pose;
  Eigen::Matrix3d F_pose;
  Eigen::Matrix<double, 3, 2> F_control;
};
MotionStep driveStep(const Eigen::Vector3d& pose, const DriveInput& u);

/// Squared Mahalanobis distance nu^T S^-1 nu of a 2-vector; +inf when S is not positive
/// definite.
double mahalanobis2(const Eigen::Vector2d& nu, const Eigen::Matrix2d& S);

/// Chi-square quantiles with 2 degrees of freedom: -2 ln(1 - p), the gate that keeps a fraction
/// p of correct 2-D innovations.
double chiSquare2(double p);

}  // namespace tessera::landmark_slam
