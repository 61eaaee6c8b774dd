// Car-like robot of docs/algorithms.md#simulated-motion-and-sensors and its waypoint steering, as
// in the seed 004 simulation (V = 3 m/s, L = 1 m, steering rate 0.2 pi rad/s, dT = 0.03 s).
//
// Model (explicit Euler step of length dt, speed V of the reference point, steering angle gamma,
// wheelbase L; all poses in the world "map" frame, metres and radians):
//   x += dt V cos(theta + gamma),  y += dt V sin(theta + gamma),  theta += dt V sin(gamma) / L.
// For constant V and gamma the reference point runs on a circle of radius L / sin(gamma).
//
// Steering: a demanded angle is clamped to +-max_steer; the actual angle moves towards it at no
// more than steer_rate (the actuator limit). The true robot moves with the true (V, gamma).
// Controls as reported to a filter are noisy, as in the seed 004 experiment: V' = V + N(0,
// sigma_speed^2), gamma' = gamma + N(0, sigma_steer^2), drawn independently every step;
// the odometry (dead reckoning) integrates (V', gamma') with the same model. Defaults: sigma_speed
// 0.3 m/s, sigma_steer 3 deg, max_steer 30 deg.
//
// Everything is deterministic given the seed.
#pragma once

#include <tessera/sim/config_check.hpp>
#include <tessera/sim/robot.hpp>
#include <tessera/sim/world.hpp>

#include <cstdint>
#include <random>

namespace tessera::sim {

struct CarLikeConfig {
  double wheelbase = 1.0;                  ///< L [m]
  double max_steer = 0.5235987755982988;   ///< |gamma| limit [rad] (30 deg)
  double steer_rate = 0.6283185307179586;  ///< |d gamma / dt| limit [rad/s] (0.2 pi)
  double sigma_speed = 0.3;                ///< reported speed noise std [m/s]
  /// Reported steering noise std [rad]: 3 deg, as 3 * (pi / 180) rounds (one ulp above 3 pi /
  /// 180), the value the landmark simulator has always used.
  double sigma_steer = 0.05235987755982989;

  template <class V>
  void visit(V& v) {
    v("wheelbase", wheelbase, "wheelbase L [m]");
    v("max_steer", max_steer, "steering angle limit [rad] (0.5236 = 30 deg), in (0, pi/2)");
    v("steer_rate", steer_rate, "steering rate limit [rad/s] (0.6283 = 0.2 pi)");
    v("sigma_speed", sigma_speed, "std of the speed reported in control/odometry [m/s]");
    v("sigma_steer", sigma_steer, "std of the steering angle reported [rad] (0.05236 = 3 deg)");
  }
  /// Finds the first bad field (keys as in visit()).
  ConfigCheck check() const;
  /// Throws std::invalid_argument naming the first bad field.
  void validate() const { check().throwIfBad("car-like robot"); }
};

/// One explicit Euler step of the the model of docs/algorithms.md#simulated-motion-and-sensors.
Pose2 carLikeStep(const Pose2& p, double speed, double steer, double dt, double wheelbase);

/// Speed and steering angle over one step.
struct DriveCommand {
  double speed = 0, steer = 0;
};

class CarLikeRobot {
 public:
  /// Throws std::invalid_argument for a bad config.
  CarLikeRobot(const Pose2& start, CarLikeConfig config, std::uint64_t seed);

  /// Moves for dt seconds at `speed` with the steering turned towards `steer_demand` (within the
  /// limits); updates truth and odometry. Returns the true command actually applied.
  DriveCommand step(double speed, double steer_demand, double dt);

  const Pose2& truePose() const { return true_pose_; }
  const Pose2& odometryPose() const { return odom_pose_; }
  /// Current true steering angle [rad].
  double steering() const { return steer_; }
  /// The noisy (speed, steering) of the last step, as a filter would receive them.
  const DriveCommand& lastReportedControl() const { return reported_; }
  double distanceTravelled() const { return travelled_; }
  const CarLikeConfig& config() const { return config_; }

 private:
  Pose2 true_pose_, odom_pose_;
  CarLikeConfig config_;
  std::mt19937_64 rng_;
  double steer_ = 0, travelled_ = 0;
  DriveCommand reported_;
};

/// Steers a car-like robot through waypoints in order: the demand is the heading error to the
/// current waypoint (clamped later by the robot); a waypoint counts as reached within
/// `tolerance`. After the last waypoint done() is true.
class WaypointSteering {
 public:
  /// Throws std::invalid_argument for fewer than two waypoints, coinciding neighbours or a
  /// non-positive tolerance.
  WaypointSteering(Route waypoints, double tolerance);

  /// Steering demand [rad] for the true pose; advances past reached waypoints.
  double demand(const Pose2& pose);
  bool done() const { return next_ >= route_.size(); }
  /// Waypoints reached so far (the first, the start, counts as reached).
  std::size_t reached() const { return next_; }
  std::size_t waypointCount() const { return route_.size(); }
  /// Length of the polyline [m].
  double totalLength() const { return routeLength(route_); }
  /// Fraction of waypoints reached, in [0, 1].
  double progress() const;
  /// On the first waypoint, facing the second.
  Pose2 startPose() const;

 private:
  Route route_;
  double tolerance_;
  std::size_t next_ = 1;
};

}  // namespace tessera::sim
