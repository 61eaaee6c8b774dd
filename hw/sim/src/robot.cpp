#include <tessera/sim/robot.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace tessera::sim {

Pose2 moveBy(const Pose2& p, double distance, double rotation) {
  const double mid = p.theta + rotation / 2;
  return {p.x + distance * std::cos(mid), p.y + distance * std::sin(mid),
          normalizeAngle(p.theta + rotation)};
}

// ---- Odometry ----

ConfigCheck OdometryNoise::check() const {
  ConfigCheck c;
  c.nonNegative("sigma_d", sigma_d).nonNegative("sigma_theta", sigma_theta);
  c.nonNegative("floor_d", floor_d).nonNegative("floor_theta", floor_theta);
  for (const auto& [key, value] : {std::pair<const char*, double>{"bias_d", bias_d},
                                   {"bias_theta", bias_theta},
                                   {"drift_theta", drift_theta}})
    c.require(std::isfinite(value) && std::abs(value) < 0.5, key,
              "must be finite and within (-0.5, 0.5)", value);
  return c;
}

Eigen::Vector2d Odometry::incrementStd(double distance, double rotation) const {
  // Wheels at rest report exactly zero: no floor noise, so a stopped robot does not drift.
  if (distance == 0 && rotation == 0) return Eigen::Vector2d::Zero();
  const double sd = noise_.sigma_d > 0 ? noise_.sigma_d * std::abs(distance) + noise_.floor_d : 0;
  const double st =
      noise_.sigma_theta > 0 ? noise_.sigma_theta * std::abs(rotation) + noise_.floor_theta : 0;
  return {sd, st};
}

Eigen::Vector2d Odometry::integrate(double distance, double rotation, std::mt19937_64& rng) {
  const Eigen::Vector2d sd = incrementStd(distance, rotation);
  // Both normals are always drawn, so the random stream does not depend on the motion.
  std::normal_distribution<double> normal(0.0, 1.0);
  const double zd = normal(rng), zt = normal(rng);
  const double d = distance * (1.0 + noise_.bias_d) + sd[0] * zd;
  const double t =
      rotation * (1.0 + noise_.bias_theta) + noise_.drift_theta * std::abs(distance) + sd[1] * zt;

  // Covariance propagation through moveBy(): Jacobians w.r.t. the pose and the increments.
  const double mid = pose_.theta + t / 2, c = std::cos(mid), s = std::sin(mid);
  Eigen::Matrix3d fx;
  fx << 1, 0, -d * s, 0, 1, d * c, 0, 0, 1;
  Eigen::Matrix<double, 3, 2> fu;
  fu << c, -d / 2 * s, s, d / 2 * c, 0, 1;
  const Eigen::Matrix2d q = sd.cwiseAbs2().asDiagonal();
  covariance_ = fx * covariance_ * fx.transpose() + fu * q * fu.transpose();

  pose_ = moveBy(pose_, d, t);
  return {d, t};
}

// ---- RouteFollower ----

ConfigCheck FollowerConfig::check() const {
  ConfigCheck c;
  c.positive("v_max", v_max).positive("w_max", w_max).positive("a_max", a_max);
  c.positive("alpha_max", alpha_max).positive("lookahead", lookahead);
  c.positive("waypoint_tolerance", waypoint_tolerance).positive("heading_gain", heading_gain);
  c.positive("turn_in_place", turn_in_place);
  return c;
}

RouteFollower::RouteFollower(std::vector<Eigen::Vector2d> waypoints, FollowerConfig config,
                             int laps)
    : config_(config) {
  config_.validate();
  if (waypoints.size() < 2)
    throw std::invalid_argument("route follower: a route needs at least two waypoints, got " +
                                std::to_string(waypoints.size()));
  if (laps < 1)
    throw std::invalid_argument("route follower: laps must be at least 1, got " +
                                std::to_string(laps));
  for (std::size_t i = 1; i < waypoints.size(); ++i)
    if ((waypoints[i] - waypoints[i - 1]).norm() < 1e-6) {
      std::ostringstream s;
      s << "route follower: waypoints " << i - 1 << " and " << i << " coincide at ("
        << waypoints[i].x() << ", " << waypoints[i].y() << ")";
      throw std::invalid_argument(s.str());
    }

  auto add = [&](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    Leg leg{a, b, (b - a).norm(), total_length_, 0};
    total_length_ += leg.length;
    legs_.push_back(leg);
  };
  const bool closed = (waypoints.back() - waypoints.front()).norm() < 1e-6;
  for (int lap = 0; lap < laps; ++lap) {
    if (lap > 0 && !closed) add(waypoints.back(), waypoints.front());
    for (std::size_t i = 1; i < waypoints.size(); ++i) add(waypoints[i - 1], waypoints[i]);
  }

  // Corner speeds: gentle bends are taken at speed, sharp ones (turned in place) almost stopped,
  // and the robot stops at the end of the route.
  for (std::size_t i = 0; i < legs_.size(); ++i) {
    if (i + 1 == legs_.size()) break;
    const Eigen::Vector2d d0 = (legs_[i].b - legs_[i].a) / legs_[i].length;
    const Eigen::Vector2d d1 = (legs_[i + 1].b - legs_[i + 1].a) / legs_[i + 1].length;
    const double turn = std::abs(std::atan2(d0.x() * d1.y() - d0.y() * d1.x(), d0.dot(d1)));
    legs_[i].corner_speed = turn < config_.turn_in_place ? config_.v_max * std::cos(turn) : 0.0;
  }
}

Pose2 RouteFollower::startPose() const {
  const Leg& l = legs_.front();
  return {l.a.x(), l.a.y(), std::atan2(l.b.y() - l.a.y(), l.b.x() - l.a.x())};
}

double RouteFollower::progress() const {
  if (done_) return 1.0;
  return std::clamp((legs_[leg_].start_s + along_) / total_length_, 0.0, 1.0);
}

Pose2 RouteFollower::jumpTo(double route_s) {
  const double s = std::clamp(route_s, 0.0, total_length_);
  leg_ = 0;
  while (leg_ + 1 < legs_.size() && legs_[leg_ + 1].start_s <= s) ++leg_;
  const Leg& leg = legs_[leg_];
  along_ = std::clamp(s - leg.start_s, 0.0, leg.length);
  last_ = {};
  stopping_ = false;
  done_ = false;
  const Eigen::Vector2d dir = (leg.b - leg.a) / leg.length;
  const Eigen::Vector2d p = leg.a + dir * along_;
  return {p.x(), p.y(), std::atan2(dir.y(), dir.x())};
}

Twist RouteFollower::command(const Pose2& pose, double dt) {
  if (done_) return {};
  if (stopping_) {
    // At the end of the route: brake within the acceleration limits, then report done.
    last_.v = std::max(0.0, last_.v - config_.a_max * dt);
    last_.omega = last_.omega > 0 ? std::max(0.0, last_.omega - config_.alpha_max * dt)
                                  : std::min(0.0, last_.omega + config_.alpha_max * dt);
    if (last_.v == 0 && last_.omega == 0) done_ = true;
    return last_;
  }
  const Eigen::Vector2d p = pose.translation();

  // Leave every leg whose end is reached (close to it, or passed its end line).
  Eigen::Vector2d dir;
  for (;;) {
    const Leg& leg = legs_[leg_];
    dir = (leg.b - leg.a) / leg.length;
    const double s = (p - leg.a).dot(dir);
    if ((p - leg.b).norm() > config_.waypoint_tolerance && s < leg.length) {
      along_ = std::clamp(s, 0.0, leg.length);
      break;
    }
    if (leg_ + 1 == legs_.size()) {
      stopping_ = true;
      along_ = leg.length;
      return command(pose, dt);
    }
    ++leg_;
  }
  const Leg& leg = legs_[leg_];

  const double carrot_s = std::min(along_ + config_.lookahead, leg.length);
  const Eigen::Vector2d carrot = leg.a + dir * carrot_s;
  const double heading_error =
      normalizeAngle(std::atan2(carrot.y() - p.y(), carrot.x() - p.x()) - pose.theta);

  double w = std::clamp(config_.heading_gain * heading_error, -config_.w_max, config_.w_max);
  double v = 0;
  if (std::abs(heading_error) < config_.turn_in_place) {
    v = config_.v_max * std::cos(heading_error);
    // Brake so as to reach the corner (a little before the tolerance circle) at its speed.
    const double to_corner = std::max(0.0, (leg.b - p).norm() - 0.5 * config_.waypoint_tolerance);
    v = std::min(v, std::sqrt(leg.corner_speed * leg.corner_speed + 2 * config_.a_max * to_corner));
    v = std::max(v, 0.02);  // never stall short of the waypoint
  }

  // Acceleration limits relative to the previous command.
  v = std::clamp(v, last_.v - config_.a_max * dt, last_.v + config_.a_max * dt);
  w = std::clamp(w, last_.omega - config_.alpha_max * dt, last_.omega + config_.alpha_max * dt);
  v = std::clamp(v, 0.0, config_.v_max);
  w = std::clamp(w, -config_.w_max, config_.w_max);
  last_ = {v, w};
  return last_;
}

// ---- BaseLimits ----

ConfigCheck BaseLimits::check() const {
  ConfigCheck c;
  c.nonNegative("a_max", a_max).nonNegative("alpha_max", alpha_max);
  return c;
}

Twist BaseLimits::follow(const Twist& current, const Twist& cmd, double dt) const {
  Twist out = cmd;
  // Unlimited returns the command itself, bit for bit (runs without limits are unchanged).
  if (a_max > 0) out.v = std::clamp(cmd.v, current.v - a_max * dt, current.v + a_max * dt);
  if (alpha_max > 0)
    out.omega =
        std::clamp(cmd.omega, current.omega - alpha_max * dt, current.omega + alpha_max * dt);
  return out;
}

// ---- DiffDriveRobot ----

DiffDriveRobot::DiffDriveRobot(const Pose2& start, OdometryNoise noise, std::uint64_t seed,
                               BaseLimits limits)
    : true_pose_(start), odometry_(start, noise), rng_(seed), limits_(limits) {}

void DiffDriveRobot::step(const Twist& cmd, double dt) {
  velocity_ = limits_.follow(velocity_, cmd, dt);
  const double distance = velocity_.v * dt, rotation = velocity_.omega * dt;
  true_pose_ = moveBy(true_pose_, distance, rotation);
  travelled_ += std::abs(distance);
  last_increment_ = odometry_.integrate(distance, rotation, rng_);
}

}  // namespace tessera::sim
