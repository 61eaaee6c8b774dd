// The one place where geometry (base/geometry: Pose2, Pose3) meets message fields:
// msg::Pose2D (x, y [m], theta [rad], optional 3x3 covariance over (x, y, theta), row-major) and
// msg::Pose3D (x, y, z [m], unit quaternion qx, qy, qz, qw). Readers copy out of the message;
// writers fill a builder in place.
#pragma once

#include <tessera/msg/common.capnp.h>
#include <tessera/msg/image.capnp.h>
#include <tessera/geometry/pose2.hpp>
#include <tessera/geometry/pose3.hpp>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace tessera {

/// The planar pose of a message; theta wrapped to (−π, π] like every Pose2.
inline Pose2 toPose2(msg::Pose2D::Reader p) {
  return {p.getX(), p.getY(), p.getTheta()};
}

/// Writes the pose and, when given, its 3x3 covariance (row-major).
inline void writePose(msg::Pose2D::Builder b, const Pose2& p,
                      const Eigen::Matrix3d* covariance = nullptr) {
  b.setX(p.x);
  b.setY(p.y);
  b.setTheta(p.theta);
  if (covariance) {
    auto c = b.initCovariance(9);
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) c.set(r * 3 + k, (*covariance)(r, k));
  }
}

/// The covariance of a pose message; false when absent or not 9 values.
inline bool readCovariance(msg::Pose2D::Reader p, Eigen::Matrix3d& out) {
  auto c = p.getCovariance();
  if (c.size() != 9) return false;
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) out(r, k) = c[r * 3 + k];
  return true;
}

/// The 3D pose of a message; the quaternion renormalised (messages carry it as four numbers).
inline Pose3 toPose3(msg::Pose3D::Reader p) {
  return {{p.getX(), p.getY(), p.getZ()},
          Eigen::Quaterniond(p.getQw(), p.getQx(), p.getQy(), p.getQz()).normalized()};
}

inline void writePose(msg::Pose3D::Builder b, const Pose3& p) {
  b.setX(p.t.x());
  b.setY(p.t.y());
  b.setZ(p.t.z());
  b.setQx(p.q.x());
  b.setQy(p.q.y());
  b.setQz(p.q.z());
  b.setQw(p.q.w());
}

}  // namespace tessera
