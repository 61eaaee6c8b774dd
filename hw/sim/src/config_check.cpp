// allFinite for the simulator's config structs.
#include <tessera/sim/config_check.hpp>

#include <cmath>

namespace tessera::sim {

bool allFinite(const Pose2& pose) {
  return std::isfinite(pose.x) && std::isfinite(pose.y) && std::isfinite(pose.theta);
}

}  // namespace tessera::sim
