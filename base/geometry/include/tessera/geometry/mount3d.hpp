// Mount3D: where a 3D sensor (a depth or RGB-D camera) sits on a planar robot. Position [m] in
// base_link (x forward, y left, z up from the floor: base_link is on the floor), orientation of
// the sensor's body frame (x forward, y left, z up) as yaw about z, then pitch about the new y
// (positive looks down), then roll about the new x [rad]. A camera's optical frame (x right,
// y down, z forward) follows from the body frame by a fixed rotation.
#pragma once

#include <Eigen/Geometry>

namespace tessera {

struct Mount3D {
  double x = 0, y = 0, z = 0, roll = 0, pitch = 0, yaw = 0;

  template <class V>
  void visit(V& v) {
    v("x", x, "[m] forward of base_link");
    v("y", y, "[m] left of base_link");
    v("z", z, "[m] above the floor");
    v("roll", roll, "[rad] about the camera's forward axis");
    v("pitch", pitch, "[rad] about its left axis; positive looks down");
    v("yaw", yaw, "[rad] about the vertical; positive turns left");
  }

  /// The sensor body (x forward, y left, z up) in base_link.
  Eigen::Isometry3d bodyToBase() const {
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.translate(Eigen::Vector3d(x, y, z));
    t.rotate(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
             Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
             Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()));
    return t;
  }
  /// The camera's optical frame (x right, y down, z forward) in base_link.
  Eigen::Isometry3d opticalToBase() const {
    Eigen::Matrix3d body_optical;  // optical axes in the body frame: x = -y, y = -z, z = +x
    body_optical << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    Eigen::Isometry3d optical = Eigen::Isometry3d::Identity();
    optical.linear() = body_optical;
    return bodyToBase() * optical;
  }
  bool isFinite() const { return Eigen::Vector<double, 6>(x, y, z, roll, pitch, yaw).allFinite(); }
};

}  // namespace tessera
