// A rigid transform as the 6 parameters Ceres' AngleAxisRotatePoint cost functions take:
// (rotation vector [rad], translation [m]). Shared by the pose refinement and the local bundle
// adjustment; internal to the library.
#pragma once

#include <Eigen/Geometry>

namespace tessera::visual_slam::detail {

inline Eigen::Isometry3d fromRvecTvec(const double* p) {
  const Eigen::Vector3d r(p[0], p[1], p[2]);
  const double angle = r.norm();
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  if (angle > 1e-12) t.linear() = Eigen::AngleAxisd(angle, r / angle).toRotationMatrix();
  t.translation() = Eigen::Vector3d(p[3], p[4], p[5]);
  return t;
}

inline void toRvecTvec(const Eigen::Isometry3d& t, double* p) {
  const Eigen::AngleAxisd aa(t.rotation());
  const Eigen::Vector3d r = aa.axis() * aa.angle();
  for (int i = 0; i < 3; ++i) {
    p[i] = r[i];
    p[3 + i] = t.translation()[i];
  }
}

}  // namespace tessera::visual_slam::detail
