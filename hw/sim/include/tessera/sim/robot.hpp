// The simulated robot: differential-drive kinematics, noisy wheel odometry, and a route follower.
//
// Units and frames: metres, radians, seconds. Poses are base_link in the world ("map") frame for
// the true state and in the "odom" frame for odometry; the odom frame equals the map frame at the
// start, so the two differ only by accumulated odometry error.
//
// Motion is integrated in fixed steps. Over one step the robot moves the increments
// (D = v dt, theta = omega dt) and moveBy() applies them at the mid-step heading (second-order
// accurate for arcs). Odometry applies the noise model of
// docs/algorithms.md#simulated-motion-and-sensors to the same increments, D' = D + N(0, (sigma_d
// |D| + floor)^2), theta' = theta + N(0, (sigma_theta |theta|
// + floor)^2), and integrates D', theta' with moveBy() too, so zero noise reproduces the true
// pose bit for bit. The noise is drawn once per step: the drift over a distance L grows like
// sigma_d * sqrt(L * step_length), so it depends on the step rate, which is why the simulator
// keeps that rate fixed.
//
// Everything is deterministic given the seed of the std::mt19937_64 passed in.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/sim/config_check.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <random>
#include <vector>

namespace tessera::sim {

/// The pose after moving forward `distance` while turning by `rotation` (mid-step heading).
Pose2 moveBy(const Pose2& p, double distance, double rotation);

struct OdometryNoise {
  double sigma_d = 0.05;      ///< distance noise std per metre of the step's distance
  double sigma_theta = 0.05;  ///< rotation noise std per radian of the step's rotation
  /// Small absolute std added per moving step when the matching sigma is non-zero, so that
  /// turning in place still gets some translation noise (and driving straight some heading
  /// noise). A step without motion gets no noise: a robot at rest does not drift.
  double floor_d = 1e-5;      ///< [m]
  double floor_theta = 1e-5;  ///< [rad]
  /// Systematic errors (a wrong wheel radius, unequal wheels): the random terms above average
  /// out over many small steps, these do not, so dead reckoning drifts by metres over a long
  /// route as real odometry does.
  double bias_d = 0.0;       ///< relative distance error: integrated distance × (1 + bias_d)
  double bias_theta = 0.0;   ///< relative rotation error: integrated rotation × (1 + bias_theta)
  double drift_theta = 0.0;  ///< [rad/m] heading drift per metre travelled

  template <class V>
  void visit(V& v) {
    v("sigma_d", sigma_d, "distance noise: std per step = sigma_d * |step distance|");
    v("sigma_theta", sigma_theta, "rotation noise: std per step = sigma_theta * |step rotation|");
    v("floor_d", floor_d, "[m] std added per moving step while sigma_d > 0");
    v("floor_theta", floor_theta, "[rad] std added per moving step while sigma_theta > 0");
    v("bias_d", bias_d, "systematic distance error: reported distance = true * (1 + bias_d)");
    v("bias_theta", bias_theta,
      "systematic rotation error: reported rotation = true * (1 + bias_theta)");
    v("drift_theta", drift_theta, "systematic heading drift per metre travelled [rad/m]");
  }
  /// Sigmas and floors >= 0; biases and drift finite and within (-0.5, 0.5).
  ConfigCheck check() const;
};

/// Dead reckoning from noisy wheel increments, with its growing covariance.
class Odometry {
 public:
  Odometry(const Pose2& start, OdometryNoise noise) : pose_(start), noise_(noise) {}

  /// Corrupts the true increments of one step, integrates them, and returns the noisy
  /// (distance, rotation) actually integrated.
  Eigen::Vector2d integrate(double distance, double rotation, std::mt19937_64& rng);

  const Pose2& pose() const { return pose_; }
  /// Covariance of pose() over (x, y, theta), propagated with the model's Jacobians.
  const Eigen::Matrix3d& covariance() const { return covariance_; }
  /// Std of the noise added to increments (distance, rotation) of that size.
  Eigen::Vector2d incrementStd(double distance, double rotation) const;
  const OdometryNoise& noise() const { return noise_; }

 private:
  Pose2 pose_;
  OdometryNoise noise_;
  Eigen::Matrix3d covariance_ = Eigen::Matrix3d::Zero();
};

struct FollowerConfig {
  double v_max = 0.5;               ///< [m/s]
  double w_max = 1.0;               ///< [rad/s]
  double a_max = 0.5;               ///< linear acceleration and braking limit [m/s^2]
  double alpha_max = 2.0;           ///< angular acceleration limit [rad/s^2]
  double lookahead = 0.4;           ///< carrot distance along the current segment [m]
  double waypoint_tolerance = 0.1;  ///< a waypoint counts as reached this close [m]
  double heading_gain = 2.0;        ///< omega = gain * heading error, before limits [1/s]
  /// Above this heading error [rad] the robot turns in place instead of driving on.
  double turn_in_place = 0.6;

  template <class V>
  void visit(V& v) {
    v("v_max", v_max, "top forward speed [m/s]");
    v("w_max", w_max, "top turn rate [rad/s]");
    v("a_max", a_max, "linear acceleration and braking limit [m/s^2]");
    v("alpha_max", alpha_max, "angular acceleration limit [rad/s^2]");
    v("lookahead", lookahead, "carrot distance along the current segment [m]");
    v("waypoint_tolerance", waypoint_tolerance, "a waypoint counts as reached this close [m]");
    v("heading_gain", heading_gain, "turn rate per radian of heading error, before limits [1/s]");
    v("turn_in_place", turn_in_place,
      "above this heading error [rad] the robot turns in place instead of driving on");
  }
  /// Every field finite and positive.
  ConfigCheck check() const;
  /// Throws std::invalid_argument naming the first bad field.
  void validate() const { check().throwIfBad("route follower"); }
};

struct Twist {
  double v = 0, omega = 0;
};

/// Drives through waypoints in order (`laps` times; between laps from the last waypoint back to
/// the first). Pure pursuit on the current segment: it steers at a carrot `lookahead` ahead of
/// its projection on the segment, slows by the cosine of the heading error, turns in place at
/// sharp corners, and brakes in time to take the next corner at a speed that fits its angle.
class RouteFollower {
 public:
  /// Throws std::invalid_argument for fewer than two waypoints, laps < 1, zero-length legs
  /// or a bad config.
  RouteFollower(std::vector<Eigen::Vector2d> waypoints, FollowerConfig config, int laps = 1);

  /// Velocity for the next `dt` seconds from the true pose (limited by the config's speeds and
  /// accelerations); advances past reached waypoints. After the last waypoint it brakes to a
  /// halt within the limits and then reports done(); zero from then on.
  Twist command(const Pose2& pose, double dt);

  bool done() const { return done_; }
  /// Fraction of the route's total length completed (by segments finished plus the projection
  /// on the current one), in [0, 1].
  double progress() const;
  /// Length of all laps [m].
  double totalLength() const { return total_length_; }
  /// Index of the leg being driven (0-based over all laps) and how many there are.
  std::size_t legIndex() const { return leg_; }
  std::size_t legCount() const { return legs_.size(); }
  /// The start pose: on the first waypoint, facing the second.
  Pose2 startPose() const;
  /// Continues the route from `route_s` metres along it (clamped to [0, totalLength()]), as
  /// after a kidnapping: returns the pose there, facing along its leg; the follower starts from
  /// standstill.
  Pose2 jumpTo(double route_s);

 private:
  struct Leg {
    Eigen::Vector2d a, b;
    double length = 0, start_s = 0;  // start_s: route distance at a
    double corner_speed = 0;         // speed allowed when reaching b
  };
  std::vector<Leg> legs_;
  FollowerConfig config_;
  double total_length_ = 0;
  std::size_t leg_ = 0;
  double along_ = 0;  // projection of the robot on the current leg [m]
  Twist last_;
  bool stopping_ = false;  // last waypoint reached, braking to a halt
  bool done_ = false;
};

/// Acceleration limits of the base's motors: a commanded velocity is followed as fast as these
/// allow (a real base cannot jump to it). 0 = unlimited, the base follows commands at once.
struct BaseLimits {
  double a_max = 0;      ///< [m/s²] linear acceleration and braking
  double alpha_max = 0;  ///< [rad/s²] angular acceleration

  template <class V>
  void visit(V& v) {
    v("a_max", a_max, "linear acceleration and braking limit of the base [m/s^2]; 0 = none");
    v("alpha_max", alpha_max, "angular acceleration limit of the base [rad/s^2]; 0 = none");
  }
  /// Both finite and >= 0.
  ConfigCheck check() const;
  /// The velocity reached after dt seconds commanded `cmd` from `current` under the limits.
  Twist follow(const Twist& current, const Twist& cmd, double dt) const;
};

/// True state, odometry and follower together, stepped at a fixed rate.
class DiffDriveRobot {
 public:
  DiffDriveRobot(const Pose2& start, OdometryNoise noise, std::uint64_t seed,
                 BaseLimits limits = {});

  /// Commands (v, omega) for dt seconds: the base's velocity follows it under its acceleration
  /// limits and is held over the step; updates the true pose and the odometry.
  void step(const Twist& cmd, double dt);
  /// Carries the true robot to `pose` and stops it; the odometry does not see it (a kidnapping).
  void teleport(const Pose2& pose) {
    true_pose_ = pose;
    velocity_ = {};
  }

  /// The velocity the base moved with in the last step (the command when unlimited).
  const Twist& velocity() const { return velocity_; }
  const Pose2& truePose() const { return true_pose_; }
  const Odometry& odometry() const { return odometry_; }
  /// Distance driven by the true robot [m].
  double distanceTravelled() const { return travelled_; }
  /// The noisy increments (distance, rotation) of the last step, as the wheels reported them.
  const Eigen::Vector2d& lastOdometryIncrement() const { return last_increment_; }
  std::mt19937_64& rng() { return rng_; }

 private:
  Pose2 true_pose_;
  Odometry odometry_;
  std::mt19937_64 rng_;
  BaseLimits limits_;
  Twist velocity_;
  double travelled_ = 0;
  Eigen::Vector2d last_increment_ = Eigen::Vector2d::Zero();
};

}  // namespace tessera::sim
