// Pushing simulated odometry and laser scans into an actor under the mock-mailbox harness, for
// the laser and line SLAM actor tests.
#pragma once

#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>

#include <cmath>
#include <vector>

#include "laser_slam/sim_scans.hpp"

namespace tessera::test {

inline Nanos stampOf(double s) {
  return static_cast<Nanos>(std::llround(s * 1e9));
}

inline void pushOdometry(ActorHarness& h, Nanos stamp, const tessera::Pose2& p) {
  h.push<msg::Odometry>("odom", [&](auto& b) {
    setHeader(b.initHeader(), stamp, "odom", 0);
    b.setChildFrameId("base_link");
    writePose(b.initPose(), tessera::Pose2{p.x, p.y, p.theta});
  });
}

inline void pushScan(ActorHarness& h, Nanos stamp, const SimScans& sim,
                     const std::vector<float>& ranges) {
  h.push<msg::LaserScan>("scan", [&](auto& b) {
    setHeader(b.initHeader(), stamp, "laser", 0);
    b.setAngleMin(static_cast<float>(sim.laser.angleMin()));
    b.setAngleIncrement(static_cast<float>(sim.laser.angleIncrement()));
    b.setRangeMin(static_cast<float>(sim.laser.range_min));
    b.setRangeMax(static_cast<float>(sim.laser.range_max));
    auto r = b.initRanges(static_cast<unsigned>(ranges.size()));
    for (unsigned i = 0; i < ranges.size(); ++i) r.set(i, ranges[i]);
  });
}

}  // namespace tessera::test
