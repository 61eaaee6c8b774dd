#include <tessera/sim/car_like.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace tessera::sim {

ConfigCheck CarLikeConfig::check() const {
  ConfigCheck c;
  c.positive("wheelbase", wheelbase);
  c.require(max_steer > 0 && max_steer < 0.5 * std::numbers::pi, "max_steer",
            "must be in (0, pi/2) rad", max_steer);
  c.positive("steer_rate", steer_rate);
  c.nonNegative("sigma_speed", sigma_speed).nonNegative("sigma_steer", sigma_steer);
  return c;
}

Pose2 carLikeStep(const Pose2& p, double speed, double steer, double dt, double wheelbase) {
  return {p.x + dt * speed * std::cos(p.theta + steer),
          p.y + dt * speed * std::sin(p.theta + steer),
          normalizeAngle(p.theta + dt * speed * std::sin(steer) / wheelbase)};
}

CarLikeRobot::CarLikeRobot(const Pose2& start, CarLikeConfig config, std::uint64_t seed)
    : true_pose_(start), odom_pose_(start), config_(config), rng_(seed) {
  config_.validate();
}

DriveCommand CarLikeRobot::step(double speed, double steer_demand, double dt) {
  const double target = std::clamp(steer_demand, -config_.max_steer, config_.max_steer);
  const double max_change = config_.steer_rate * dt;
  steer_ = std::clamp(steer_ + std::clamp(target - steer_, -max_change, max_change),
                      -config_.max_steer, config_.max_steer);
  true_pose_ = carLikeStep(true_pose_, speed, steer_, dt, config_.wheelbase);
  travelled_ += std::abs(speed) * dt;

  // Both normals are always drawn, so the stream does not depend on the motion.
  std::normal_distribution<double> normal(0.0, 1.0);
  const double nv = normal(rng_), ng = normal(rng_);
  reported_ = {speed + config_.sigma_speed * nv, steer_ + config_.sigma_steer * ng};
  odom_pose_ = carLikeStep(odom_pose_, reported_.speed, reported_.steer, dt, config_.wheelbase);
  return {speed, steer_};
}

WaypointSteering::WaypointSteering(Route waypoints, double tolerance)
    : route_(std::move(waypoints)), tolerance_(tolerance) {
  if (route_.size() < 2)
    throw std::invalid_argument("waypoint steering: needs at least two waypoints, got " +
                                std::to_string(route_.size()));
  if (!(tolerance > 0) || !std::isfinite(tolerance))
    throw std::invalid_argument("waypoint steering: tolerance must be positive");
  for (std::size_t i = 1; i < route_.size(); ++i)
    if ((route_[i] - route_[i - 1]).norm() < 1e-6)
      throw std::invalid_argument("waypoint steering: waypoints " + std::to_string(i - 1) +
                                  " and " + std::to_string(i) + " coincide");
}

double WaypointSteering::demand(const Pose2& pose) {
  while (next_ < route_.size() && (route_[next_] - pose.translation()).norm() <= tolerance_)
    ++next_;
  if (done()) return 0.0;
  const Eigen::Vector2d d = route_[next_] - pose.translation();
  return normalizeAngle(std::atan2(d.y(), d.x()) - pose.theta);
}

double WaypointSteering::progress() const {
  return static_cast<double>(next_) / static_cast<double>(route_.size());
}

Pose2 WaypointSteering::startPose() const {
  const Eigen::Vector2d d = route_[1] - route_[0];
  return {route_[0].x(), route_[0].y(), std::atan2(d.y(), d.x())};
}

}  // namespace tessera::sim
