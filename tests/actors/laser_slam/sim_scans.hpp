// Simulated laser + drifting odometry along the built-in room's loop, for the laser SLAM tests:
// the robot turns in place towards each waypoint, then drives to it; one scan every 0.1 m or
// 0.1 rad. Odometry has systematic scale and heading errors, so it drifts a lot.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>
#include <tessera/sim/ray_caster.hpp>
#include <tessera/sim/robot.hpp>
#include <tessera/sim/world.hpp>

#include <cmath>
#include <random>
#include <vector>

namespace tessera::test {

struct SimScan {
  double stamp_s = 0;
  std::vector<float> ranges;
  tessera::Pose2 truth;     // base_link in the world
  tessera::Pose2 odometry;  // base_link in odom (starts at the true start pose)
};

struct SimScans {
  sim::LaserConfig laser;
  std::vector<SimScan> scans;

  tessera::grid::RangeScan range(const SimScan& s) const {
    return {s.ranges, laser.angleMin(), laser.angleIncrement(), laser.range_min, laser.range_max};
  }
};

inline SimScans simulateRoomLoop(int laps = 1, std::uint64_t seed = 7) {
  static const sim::World world = sim::World::builtinRoom();
  SimScans out;
  out.laser.range_max = 30.0;
  out.laser.range_noise = 0.01;
  const sim::LaserModel model(world, out.laser);
  std::mt19937_64 rng(seed);

  const auto& route = world.defaultRoute();
  tessera::Pose2 truth(route[0],
                       std::atan2(route[1].y() - route[0].y(), route[1].x() - route[0].x()));
  tessera::Pose2 odom = truth;
  double t = 0;
  const auto emit = [&] {
    SimScan s;
    s.stamp_s = t;
    s.ranges = model.scan(tessera::Pose2{truth.x, truth.y, truth.theta}, rng);
    s.truth = truth;
    s.odometry = odom;
    out.scans.push_back(std::move(s));
    t += 0.25;
  };
  const auto step = [&](double dist, double rot) {
    truth = truth * tessera::Pose2(dist, 0.0, rot);
    // Systematic errors: 3 % distance scale, 4 % rotation scale, 0.6 deg of heading per metre.
    odom = odom * tessera::Pose2(dist * 1.03, 0.0, rot * 1.04 + 0.01 * dist);
  };
  emit();
  for (int lap = 0; lap < laps; ++lap) {
    for (std::size_t k = 1; k <= route.size(); ++k) {
      const Eigen::Vector2d goal = route[k % route.size()];
      const double heading = std::atan2(goal.y() - truth.y, goal.x() - truth.x);
      for (double turn = tessera::angleDiff(heading, truth.theta); std::abs(turn) > 1e-9;) {
        const double r = std::clamp(turn, -0.1, 0.1);
        step(0.0, r);
        turn -= r;
        emit();
      }
      for (double left = (goal - truth.translation()).norm(); left > 1e-9;) {
        const double d = std::min(left, 0.1);
        step(d, 0.0);
        left -= d;
        emit();
      }
    }
  }
  return out;
}

}  // namespace tessera::test
