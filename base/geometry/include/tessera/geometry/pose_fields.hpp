// PoseFields: a Pose2 as an option group. In an options struct's visit(),
// `PoseFields f{pose}; v("mount", f, "...")` reads `mount: {x [m], y [m], theta [rad]}`.
#pragma once

#include <tessera/geometry/pose2.hpp>

namespace tessera {

struct PoseFields {
  Pose2& pose;
  template <class V>
  void visit(V& v) {
    v("x", pose.x, "[m]");
    v("y", pose.y, "[m]");
    v("theta", pose.theta, "[rad]");
  }
};

}  // namespace tessera
