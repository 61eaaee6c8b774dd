// SE(3): rigid motions in space, the pose type of 3D pose graphs and RGB-D trajectories.
//
// A Pose3 {t, q} is the pose of a child frame in a parent frame: translation t in metres and a
// unit quaternion q, mapping child coordinates to parent coordinates: p_parent = q * p_child + t.
// Composition follows frames as for Pose2 (pose2.hpp): a * b is the pose of b's child in a's
// parent. Header-only, no allocation.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace tessera {

struct Pose3 {
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();  ///< unit norm

  /// Composition this ⊕ b (the rotation renormalised, so long chains stay unit).
  Pose3 operator*(const Pose3& b) const { return {t + q * b.t, (q * b.q).normalized()}; }
  Pose3 inverse() const {
    const Eigen::Quaterniond qi = q.conjugate();
    return {-(qi * t), qi};
  }

  /// From and to Eigen's isometry (OpenCV- and Eigen-facing code holds poses that way).
  static Pose3 fromIsometry(const Eigen::Isometry3d& T) {
    return {T.translation(), Eigen::Quaterniond(T.rotation()).normalized()};
  }
  Eigen::Isometry3d isometry() const {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = q.toRotationMatrix();
    T.translation() = t;
    return T;
  }
};

}  // namespace tessera
