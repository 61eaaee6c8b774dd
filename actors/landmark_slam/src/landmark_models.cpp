#include <tessera/landmark_slam/landmark_models.hpp>

#include <Eigen/Cholesky>

#include <cmath>
#include <limits>

namespace tessera::landmark_slam {
namespace {

// Sensor position for the base pose and d(sensor xy)/d(theta).
struct SensorAt {
  Eigen::Vector2d xy, dxy_dtheta;
  double theta;
};

SensorAt sensorAt(const Eigen::Vector3d& pose, const Pose2& mount) {
  const double c = std::cos(pose[2]), s = std::sin(pose[2]);
  SensorAt out;
  out.xy = {pose[0] + c * mount.x - s * mount.y, pose[1] + s * mount.x + c * mount.y};
  out.dxy_dtheta = {-s * mount.x - c * mount.y, c * mount.x - s * mount.y};
  out.theta = pose[2] + mount.theta;
  return out;
}

}  // namespace

RangeBearingPrediction predictRangeBearing(const Eigen::Vector3d& pose, const Eigen::Vector2d& m,
                                           const Pose2& mount) {
  const SensorAt s = sensorAt(pose, mount);
  const Eigen::Vector2d d = m - s.xy;
  const double q = d.squaredNorm(), r = std::sqrt(q);
  RangeBearingPrediction out;
  out.z = {r, normalizeAngle(std::atan2(d.y(), d.x()) - s.theta)};
  // Rows: d(range), d(bearing) with respect to the landmark; the sensor moves the other way.
  out.H_landmark << d.x() / r, d.y() / r, -d.y() / q, d.x() / q;
  out.H_pose.leftCols<2>() = -out.H_landmark;
  out.H_pose.col(2) = -out.H_landmark * s.dxy_dtheta;
  out.H_pose(1, 2) -= 1.0;
  return out;
}

LandmarkFromObservation landmarkFromRangeBearing(const Eigen::Vector3d& pose,
                                                 const Eigen::Vector2d& z, const Pose2& mount) {
  const SensorAt s = sensorAt(pose, mount);
  const double a = s.theta + z[1], c = std::cos(a), sn = std::sin(a);
  LandmarkFromObservation out;
  out.m = s.xy + z[0] * Eigen::Vector2d(c, sn);
  out.G_z << c, -z[0] * sn, sn, z[0] * c;
  out.G_pose.leftCols<2>().setIdentity();
  out.G_pose.col(2) = s.dxy_dtheta + z[0] * Eigen::Vector2d(-sn, c);
  return out;
}

MotionStep driveStep(const Eigen::Vector3d& pose, const DriveInput& u) {
  MotionStep out;
  const double dt = u.dt, v = u.speed;
  const double heading = u.carLike() ? pose[2] + u.steer : pose[2];
  const double c = std::cos(heading), s = std::sin(heading);
  out.pose = pose + Eigen::Vector3d(
                        dt * v * c, dt * v * s,
                        u.carLike() ? dt * v * std::sin(u.steer) / u.wheelbase : dt * u.turn_rate);
  out.pose[2] = normalizeAngle(out.pose[2]);
  out.F_pose.setIdentity();
  out.F_pose(0, 2) = -dt * v * s;
  out.F_pose(1, 2) = dt * v * c;
  out.F_control.col(0) << dt * c, dt * s, u.carLike() ? dt * std::sin(u.steer) / u.wheelbase : 0;
  if (u.carLike())
    out.F_control.col(1) << -dt * v * s, dt * v * c, dt * v * std::cos(u.steer) / u.wheelbase;
  else
    out.F_control.col(1) << 0, 0, dt;
  return out;
}

double mahalanobis2(const Eigen::Vector2d& nu, const Eigen::Matrix2d& S) {
  const Eigen::LLT<Eigen::Matrix2d> llt(S);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  return nu.dot(llt.solve(nu));
}

double chiSquare2(double p) {
  return -2.0 * std::log1p(-p);
}

}  // namespace tessera::landmark_slam
