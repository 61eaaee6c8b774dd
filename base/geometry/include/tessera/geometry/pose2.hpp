// SE(2): rigid motions of the plane, the pose type of every planar SLAM and navigation core.
//
// A Pose2 {x, y, theta} is the pose of a child frame in a parent frame: x, y in metres, theta in
// radians (counter-clockwise), and maps child coordinates to parent coordinates:
//   p_parent = R(theta) * p_child + (x, y).
// Composition follows frames: if a is the pose of B in A and b the pose of C in B, then
// a * b (a ⊕ b) is the pose of C in A. between(a, b) = a⁻¹ * b is the pose of b seen from a.
// All angles produced here are normalised to (−π, π]. Header-only, no allocation.
#pragma once

#include <Eigen/Core>

#include <cmath>
#include <numbers>

namespace tessera {

/// Wraps an angle [rad] to (−π, π]. Non-finite input is returned unchanged.
inline double normalizeAngle(double a) {
  if (!std::isfinite(a)) return a;
  // remainder() is exact and lands in [−π, π]; only −π has to move to the other end.
  double r = std::remainder(a, 2.0 * std::numbers::pi);
  if (r <= -std::numbers::pi) r += 2.0 * std::numbers::pi;
  return r;
}

/// Shortest signed angular difference a − b, in (−π, π].
inline double angleDiff(double a, double b) {
  return normalizeAngle(a - b);
}

struct Pose2 {
  double x = 0.0;      ///< [m]
  double y = 0.0;      ///< [m]
  double theta = 0.0;  ///< [rad], kept in (−π, π] by every operation below

  Pose2() = default;
  Pose2(double x_, double y_, double theta_) : x(x_), y(y_), theta(normalizeAngle(theta_)) {}
  Pose2(const Eigen::Vector2d& t, double theta_) : Pose2(t.x(), t.y(), theta_) {}

  static Pose2 identity() { return {}; }

  Eigen::Vector2d translation() const { return {x, y}; }
  Eigen::Matrix2d rotation() const {
    const double c = std::cos(theta), s = std::sin(theta);
    return (Eigen::Matrix2d() << c, -s, s, c).finished();
  }
  /// Homogeneous 3x3 matrix [R t; 0 1].
  Eigen::Matrix3d matrix() const {
    Eigen::Matrix3d m = Eigen::Matrix3d::Identity();
    m.topLeftCorner<2, 2>() = rotation();
    m.topRightCorner<2, 1>() = translation();
    return m;
  }
  /// From a homogeneous matrix; the rotation part is read through atan2, so it need not be
  /// exactly orthonormal.
  static Pose2 fromMatrix(const Eigen::Matrix3d& m) {
    return {m(0, 2), m(1, 2), std::atan2(m(1, 0), m(0, 0))};
  }
  /// (x, y, theta) as a vector, e.g. for residuals and covariances.
  Eigen::Vector3d vector() const { return {x, y, theta}; }

  /// Composition this ⊕ b.
  Pose2 operator*(const Pose2& b) const {
    const double c = std::cos(theta), s = std::sin(theta);
    return {x + c * b.x - s * b.y, y + s * b.x + c * b.y, theta + b.theta};
  }
  /// Maps a point from the child frame to the parent frame.
  Eigen::Vector2d operator*(const Eigen::Vector2d& p) const {
    const double c = std::cos(theta), s = std::sin(theta);
    return {x + c * p.x() - s * p.y(), y + s * p.x() + c * p.y()};
  }
  Pose2 inverse() const {
    const double c = std::cos(theta), s = std::sin(theta);
    return {-c * x - s * y, s * x - c * y, -theta};
  }

  bool isFinite() const { return std::isfinite(x) && std::isfinite(y) && std::isfinite(theta); }
};

/// a ⊕ b.
inline Pose2 compose(const Pose2& a, const Pose2& b) {
  return a * b;
}
/// The pose of b in a's frame: a⁻¹ ⊕ b (so compose(a, between(a, b)) == b).
inline Pose2 between(const Pose2& a, const Pose2& b) {
  return a.inverse() * b;
}
/// Maps point p from pose's child frame to its parent frame.
inline Eigen::Vector2d transformPoint(const Pose2& pose, const Eigen::Vector2d& p) {
  return pose * p;
}

/// Linear interpolation of position and shortest-arc interpolation of heading; t in [0, 1]
/// gives a at 0 and b at 1. Good for poses close in time (sensor stamp between two poses).
inline Pose2 interpolate(const Pose2& a, const Pose2& b, double t) {
  return {a.x + t * (b.x - a.x), a.y + t * (b.y - a.y), a.theta + t * angleDiff(b.theta, a.theta)};
}

}  // namespace tessera
