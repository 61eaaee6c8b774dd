// Pose2D message fields as an SE(2) pose, for the laser SLAM actors.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/messages/types.hpp>

namespace tessera::laser_slam {

inline tessera::Pose2 toPose2(msg::Pose2D::Reader p) {
  const PoseXYT x = readPose(p);
  return {x.x, x.y, x.theta};
}

}  // namespace tessera::laser_slam
