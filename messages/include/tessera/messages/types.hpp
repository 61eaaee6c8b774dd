// All Tessera message schemas plus small helpers for fields every family uses (header, pose).
#pragma once

#include <tessera/msg/common.capnp.h>
#include <tessera/msg/map.capnp.h>
#include <tessera/msg/sensor.capnp.h>

#include <Eigen/Core>

#include <cstdint>
#include <string_view>

namespace tessera {

/// Planar pose as plain numbers (x [m], y [m], theta [rad]) for message glue; SE(2) math lives
/// in actors/common.
struct PoseXYT {
  double x = 0, y = 0, theta = 0;
};

inline void setHeader(msg::Header::Builder h, std::int64_t stamp_ns, std::string_view frame,
                      std::uint64_t seq) {
  h.setStampNs(stamp_ns);
  h.setFrameId(capnp::Text::Reader(frame.data(), frame.size()));
  h.setSeq(seq);
}

inline PoseXYT readPose(msg::Pose2D::Reader p) {
  return {p.getX(), p.getY(), p.getTheta()};
}

/// Writes pose and, when given, its 3x3 covariance (row-major).
inline void writePose(msg::Pose2D::Builder b, const PoseXYT& p,
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

/// The covariance of a pose message; returns false when absent or not 9 values.
inline bool readCovariance(msg::Pose2D::Reader p, Eigen::Matrix3d& out) {
  auto c = p.getCovariance();
  if (c.size() != 9) return false;
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) out(r, k) = c[r * 3 + k];
  return true;
}

}  // namespace tessera
