// What the simulator's config structs share: ConfigCheck (base/config) for their fields, and the
// sensor mount pose as an option group: PoseFields lets a Pose2 field appear in a visit() as the
// group {x [m], y [m], theta [rad]}.
#pragma once

#include <tessera/config/config_check.hpp>
#include <tessera/geometry/pose2.hpp>
#include <tessera/geometry/pose_fields.hpp>

namespace tessera::sim {

using tessera::ConfigCheck;
using tessera::ConfigProblem;

/// A pose as an option group: `v("mount", PoseFields{mount}, ...)` reads `mount: {x, y, theta}`.
using tessera::PoseFields;

/// Whether every component of the pose is finite.
bool allFinite(const Pose2& pose);

}  // namespace tessera::sim
