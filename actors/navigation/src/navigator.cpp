// Navigator: plan, follow with the dynamic window, watch progress, recover (see the header).
#include <tessera/navigation/navigator.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace tessera::navigation {
namespace {

bool finite(const Pose2& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.theta);
}

std::string where(const Pose2& p) {
  std::ostringstream s;
  s.precision(3);
  s << "(" << p.x << ", " << p.y << ")";
  return s.str();
}

// Closest point of segment ab to p, as the parameter t in [0, 1].
double project(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& p) {
  const Eigen::Vector2d d = b - a;
  const double l2 = d.squaredNorm();
  if (l2 <= 0) return 0;
  return std::clamp((p - a).dot(d) / l2, 0.0, 1.0);
}

}  // namespace

void NavigatorOptions::validate() const {
  const auto need = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(what);
  };
  planner.validate();
  dwa.validate();
  ant_colony_options.validate();
  need(std::isfinite(tolerance_xy) && tolerance_xy > 0, "tolerance_xy must be > 0");
  need(!std::isnan(tolerance_yaw) && tolerance_yaw > 0, "tolerance_yaw must be > 0");
  need(shorten_max_cost >= 0 && shorten_max_cost <= cost::kMaxTraversable,
       "shorten_max_cost must be in [0, 252]");
  need(std::isfinite(lookahead) && lookahead > 0, "lookahead must be > 0");
  need(std::isfinite(replan_period) && replan_period >= 0, "replan_period must be >= 0");
  need(std::isfinite(stuck_time) && stuck_time > 0, "stuck_time must be > 0");
  need(std::isfinite(stuck_progress) && stuck_progress > 0, "stuck_progress must be > 0");
  need(std::isfinite(turn_gain) && turn_gain > 0, "turn_gain must be > 0");
  need(std::isfinite(start_search_radius) && start_search_radius >= 0,
       "start_search_radius must be >= 0");
  need(std::isfinite(recovery.rotate_rate) && recovery.rotate_rate > 0,
       "recovery.rotate_rate must be > 0");
  need(std::isfinite(recovery.rotate_angle) && recovery.rotate_angle > 0,
       "recovery.rotate_angle must be > 0");
  need(std::isfinite(recovery.backup_speed) && recovery.backup_speed > 0,
       "recovery.backup_speed must be > 0");
  need(std::isfinite(recovery.backup_distance) && recovery.backup_distance >= 0,
       "recovery.backup_distance must be >= 0");
  need(recovery.max_attempts >= 0, "recovery.max_attempts must be >= 0");
}

std::string_view stateName(NavState s) {
  for (const auto& [name, value] : optionNames(s))
    if (value == s) return name;
  return "?";
}

Navigator::Navigator(const NavigatorOptions& options)
    : options_((options.validate(), options)), planner_(options.planner), dwa_(options.dwa) {}

std::string Navigator::setGoal(const Pose2& goal, const Costmap& costmap, double tolerance_xy,
                               double tolerance_yaw) {
  cancel();
  std::string why;
  const Eigen::Vector2i cell = costmap.cellOf(goal.translation());
  if (!finite(goal)) {
    why = "goal has a non-finite coordinate";
  } else if (costmap.empty() || !costmap.contains(cell)) {
    why = "goal " + where(goal) + " is off the map";
  } else if (const std::uint8_t c = costmap.at(cell); c == cost::kUnknown) {
    if (!options_.planner.allow_unknown) why = "goal " + where(goal) + " is in unknown space";
  } else if (c >= cost::kInscribed) {
    why = "goal " + where(goal) +
          (c == cost::kLethal ? " is on an obstacle"
                              : " is closer to an obstacle than the "
                                "robot's inscribed radius");
  }
  if (!why.empty()) {
    state_ = NavState::kRefused;
    reason_ = why;
    return why;
  }
  goal_ = goal;
  tolerance_xy_ =
      std::isfinite(tolerance_xy) && tolerance_xy > 0 ? tolerance_xy : options_.tolerance_xy;
  tolerance_yaw_ =
      !std::isnan(tolerance_yaw) && tolerance_yaw > 0 ? tolerance_yaw : options_.tolerance_yaw;
  state_ = NavState::kDriving;
  need_plan_ = true;
  attempts_ = 0;
  best_remaining_ = std::numeric_limits<double>::infinity();
  best_time_ = std::numeric_limits<double>::quiet_NaN();  // set by the first step
  return "";
}

void Navigator::cancel() {
  goal_.reset();
  state_ = NavState::kIdle;
  reason_.clear();
  path_.clear();
  progress_index_ = 0;
}

NavCommand Navigator::fail(const std::string& why) {
  state_ = NavState::kFailed;
  reason_ = why;
  NavCommand c;
  c.state = state_;
  c.reason = why;
  return c;
}

bool Navigator::plan(const Pose2& pose, const Costmap& costmap, std::string* why) {
  const auto t0 = std::chrono::steady_clock::now();
  Eigen::Vector2i start = costmap.cellOf(pose.translation());
  const auto passable = [&](const Eigen::Vector2i& c) {
    if (!costmap.contains(c)) return false;
    const std::uint8_t v = costmap.at(c);
    return v < cost::kInscribed || (v == cost::kUnknown && options_.planner.allow_unknown);
  };
  if (!passable(start)) {
    // The robot brushes an inflated obstacle (or the costmap lags it): plan from the nearest
    // passable cell around it.
    const int r = static_cast<int>(std::ceil(options_.start_search_radius / costmap.resolution));
    std::optional<Eigen::Vector2i> best;
    int best_d2 = std::numeric_limits<int>::max();
    for (int dy = -r; dy <= r; ++dy)
      for (int dx = -r; dx <= r; ++dx) {
        const int d2 = dx * dx + dy * dy;
        const Eigen::Vector2i c = start + Eigen::Vector2i(dx, dy);
        if (d2 <= r * r && d2 < best_d2 && passable(c)) {
          best = c;
          best_d2 = d2;
        }
      }
    if (best) start = *best;
  }
  const GridPath found = planner_.plan(costmap, start, costmap.cellOf(goal_->translation()));
  ++stats_.plans;
  if (found.landmarks_used) ++stats_.landmark_plans;
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  stats_.plan_ms_total += ms;
  stats_.plan_ms_max = std::max(stats_.plan_ms_max, ms);
  if (!found.ok()) {
    ++stats_.plan_failures;
    *why = "no path: " + std::string(statusName(found.status));
    return false;
  }
  std::vector<Eigen::Vector2i> cells = found.cells;
  if (options_.shorten)
    cells = shortenPath(costmap, cells, static_cast<std::uint8_t>(options_.shorten_max_cost));
  if (options_.ant_colony && cells.size() > 2)
    cells = AntColonyRefiner(options_.ant_colony_options).refine(costmap, cells);
  path_.clear();
  path_.push_back(pose.translation());
  for (std::size_t i = 1; i + 1 < cells.size(); ++i) path_.push_back(costmap.cellCenter(cells[i]));
  path_.push_back(goal_->translation());
  progress_index_ = 0;
  return true;
}

bool Navigator::pathBlocked(const Costmap& costmap) const {
  // Segments ahead of the one the robot is on must stay in line of sight; the robot's own
  // segment is not checked behind it, where it may brush an inflated cell.
  for (std::size_t k = progress_index_ + 1; k + 1 < path_.size(); ++k) {
    const Eigen::Vector2i a = costmap.cellOf(path_[k]), b = costmap.cellOf(path_[k + 1]);
    if (!costmap.contains(a) || !costmap.contains(b)) return true;
    if (!lineOfSight(costmap, a, b, cost::kMaxTraversable, options_.planner.allow_unknown))
      return true;
  }
  if (progress_index_ + 1 < path_.size()) {
    const Eigen::Vector2i next = costmap.cellOf(path_[progress_index_ + 1]);
    if (!costmap.contains(next) || costmap.at(next) >= cost::kInscribed) {
      // The goal cell itself may be unknown when allowed; anything else is blocked.
      return !(costmap.contains(next) && costmap.at(next) == cost::kUnknown &&
               options_.planner.allow_unknown);
    }
  }
  return false;
}

double Navigator::remaining(const Pose2& pose) const {
  if (path_.size() < 2) return (goal_->translation() - pose.translation()).norm();
  double d = (path_[progress_index_ + 1] - pose.translation()).norm();
  for (std::size_t k = progress_index_ + 1; k + 1 < path_.size(); ++k)
    d += (path_[k + 1] - path_[k]).norm();
  return d;
}

Eigen::Vector2d Navigator::lookaheadPoint(const Pose2& pose) {
  const Eigen::Vector2d p = pose.translation();
  // Move on to the next segment once the robot is nearer to it than to the current one.
  while (progress_index_ + 2 < path_.size()) {
    const auto dist = [&](std::size_t k) {
      const double t = project(path_[k], path_[k + 1], p);
      return (path_[k] + t * (path_[k + 1] - path_[k]) - p).norm();
    };
    if (dist(progress_index_ + 1) <= dist(progress_index_) ||
        project(path_[progress_index_], path_[progress_index_ + 1], p) >= 1.0)
      ++progress_index_;
    else
      break;
  }
  std::size_t k = progress_index_;
  const double t = project(path_[k], path_[k + 1], p);
  Eigen::Vector2d at = path_[k] + t * (path_[k + 1] - path_[k]);
  double left = options_.lookahead;
  while (true) {
    const double seg = (path_[k + 1] - at).norm();
    if (seg >= left || k + 2 >= path_.size())
      return seg >= left ? at + (path_[k + 1] - at) * (left / seg) : path_[k + 1];
    left -= seg;
    at = path_[k + 1];
    ++k;
  }
}

NavCommand Navigator::startRecovery(double now, const Pose2& pose, const DistanceField& obstacles,
                                    const std::string& why) {
  ++attempts_;
  if (attempts_ > options_.recovery.max_attempts)
    return fail(why + "; gave up after " + std::to_string(options_.recovery.max_attempts) +
                " recoveries");
  ++stats_.recoveries;
  state_ = NavState::kRecovering;
  recovery_start_ = pose;
  recovery_start_time_ = now;
  recovery_turned_ = 0;
  last_theta_ = pose.theta;
  // Alternate: turn in place (the obstacle layer is cleared and rebuilt by looking around), then
  // back up where the way back is clear.
  const Eigen::Vector2d behind =
      pose.translation() - options_.recovery.backup_distance *
                               Eigen::Vector2d(std::cos(pose.theta), std::sin(pose.theta));
  const bool can_back_up = options_.recovery.backup_distance > 0 &&
                           obstacles.at(behind) > options_.dwa.footprint_radius + 0.05;
  recovery_kind_ = (attempts_ % 2 == 0 && can_back_up) ? 1 : 0;
  reason_ = why + (recovery_kind_ == 0 ? "; recovery: clear and rotate" : "; recovery: back up");
  NavCommand c = recover(now, pose, obstacles);
  c.clear_obstacles = recovery_kind_ == 0;
  return c;
}

NavCommand Navigator::recover(double now, const Pose2& pose, const DistanceField& obstacles) {
  NavCommand c;
  c.state = NavState::kRecovering;
  c.reason = reason_;
  c.distance_remaining = remaining(pose);
  bool done = false;
  const double elapsed = now - recovery_start_time_;
  if (recovery_kind_ == 0) {
    recovery_turned_ += std::abs(normalizeAngle(pose.theta - last_theta_));
    last_theta_ = pose.theta;
    const double expected = options_.recovery.rotate_angle / options_.recovery.rotate_rate;
    done = recovery_turned_ >= options_.recovery.rotate_angle || elapsed > 2 * expected + 2;
    if (!done) c.velocity = {0, options_.recovery.rotate_rate};
  } else {
    const double moved = (pose.translation() - recovery_start_.translation()).norm();
    const Eigen::Vector2d back =
        pose.translation() - 0.1 * Eigen::Vector2d(std::cos(pose.theta), std::sin(pose.theta));
    const bool clear = obstacles.at(back) > options_.dwa.footprint_radius + 0.02;
    const double expected = options_.recovery.backup_distance / options_.recovery.backup_speed;
    done = moved >= options_.recovery.backup_distance || !clear || elapsed > 2 * expected + 2;
    if (!done) c.velocity = {-options_.recovery.backup_speed, 0};
  }
  if (done) {
    state_ = NavState::kDriving;
    need_plan_ = true;
    best_remaining_ = std::numeric_limits<double>::infinity();
    best_time_ = now;
    c.state = state_;
    c.velocity = {};
  }
  return c;
}

NavCommand Navigator::step(double now, const Pose2& pose, const Velocity& current,
                           const Costmap& costmap, const DistanceField& obstacles) {
  NavCommand c;
  c.state = state_;
  c.reason = reason_;
  has_window_ = false;
  if (!goal_ || isFinal(state_) || state_ == NavState::kIdle) return c;
  if (!finite(pose) || !std::isfinite(current.v) || !std::isfinite(current.w) ||
      !std::isfinite(now))
    return c;
  if (std::isnan(best_time_)) best_time_ = now;
  if (state_ == NavState::kRecovering) return recover(now, pose, obstacles);

  const double to_goal = (goal_->translation() - pose.translation()).norm();
  if (state_ == NavState::kTurning && to_goal > 2 * tolerance_xy_) state_ = NavState::kDriving;
  if (state_ == NavState::kTurning || to_goal <= tolerance_xy_) {
    state_ = NavState::kTurning;
    c.state = state_;
    c.distance_remaining = to_goal;
    const double err = normalizeAngle(goal_->theta - pose.theta);
    if (std::isinf(tolerance_yaw_) || std::abs(err) <= tolerance_yaw_) {
      state_ = NavState::kReached;
      reason_.clear();
      c.state = state_;
      c.reason.clear();
      return c;
    }
    // Turn in place, at least slowly enough to finish, at most the dynamic window's limit.
    const double w = std::clamp(options_.turn_gain * err, -options_.dwa.max_turn_rate,
                                options_.dwa.max_turn_rate);
    c.velocity = {0, std::copysign(std::max(std::abs(w), 0.1), err)};
    return c;
  }

  std::string why;
  const bool periodic =
      options_.replan_period > 0 && now - last_plan_time_ >= options_.replan_period;
  const bool blocked = !need_plan_ && pathBlocked(costmap);
  if (need_plan_ || periodic || blocked) {
    last_plan_time_ = now;
    if (!plan(pose, costmap, &why)) return startRecovery(now, pose, obstacles, why);
    need_plan_ = false;
    c.replanned = true;
  }
  const Eigen::Vector2d target = lookaheadPoint(pose);
  window_ = dwa_.choose(pose, current, target, obstacles, keep_arcs_);
  has_window_ = true;
  const DynamicWindowResult& r = window_;
  const double left = remaining(pose);
  c.distance_remaining = left;
  if (!r.ok) {
    ++stats_.dwa_failures;
    return startRecovery(now, pose, obstacles, "no admissible velocity");
  }
  // A new path may be longer than the old one (an obstacle appeared): progress counts from its
  // length on, while the time since the last progress keeps running.
  if (c.replanned && left > best_remaining_) best_remaining_ = left;
  if (left < best_remaining_ - options_.stuck_progress) {
    best_remaining_ = left;
    best_time_ = now;
  } else if (now - best_time_ > options_.stuck_time) {
    return startRecovery(
        now, pose, obstacles,
        "no progress for " + std::to_string(static_cast<int>(options_.stuck_time)) + " s");
  }
  state_ = NavState::kDriving;
  c.state = state_;
  c.reason.clear();
  c.velocity = r.command;
  return c;
}

}  // namespace tessera::navigation
