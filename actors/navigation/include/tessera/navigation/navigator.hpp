// Navigator: the decision loop that drives a robot to a goal (docs/algorithms.md#navigation):
// plan a global path on the costmap, follow it with the dynamic window, notice when the path is
// blocked or the robot makes no progress, recover (rotate in place, back up, ask for the
// obstacles to be cleared), give up with a reason when recoveries do not help.
//
// Each call of step() is one control period: the robot's map pose and velocity, the planning
// costmap (static layer + obstacles, inflated) and the obstacles' distance field for the dynamic
// window (usually from the same costmap) go in, a velocity command and the state come out. The
// goal is reached when the position is within tolerance_xy and then the heading within
// tolerance_yaw (the robot turns in place at the end). Time is the caller's clock [s]; poses are
// in the map frame [m, rad]. Message-free and single-threaded: the navigation actor owns one.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/navigation/ant_colony.hpp>
#include <tessera/navigation/costmap.hpp>
#include <tessera/navigation/dynamic_window.hpp>
#include <tessera/navigation/grid_planner.hpp>

#include <Eigen/Core>

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tessera::navigation {

struct RecoveryOptions {
  double rotate_rate = 0.8;       ///< [rad/s] turning in place
  double rotate_angle = 6.2832;   ///< [rad] one full turn: the sensors see all around
  double backup_speed = 0.1;      ///< [m/s]
  double backup_distance = 0.25;  ///< [m] only where the way back is clear
  int max_attempts = 4;           ///< recoveries per goal before it fails

  template <class V>
  void visit(V& v) {
    v("rotate_rate", rotate_rate, "[rad/s] turn rate of the rotate recovery");
    v("rotate_angle", rotate_angle, "[rad] how far the rotate recovery turns");
    v("backup_speed", backup_speed, "[m/s] speed of the back-up recovery");
    v("backup_distance", backup_distance, "[m] distance of the back-up recovery");
    v("max_attempts", max_attempts, "recoveries per goal before it fails");
  }
};

struct NavigatorOptions {
  GridPlannerOptions planner;
  bool shorten = true;  ///< line-of-sight shortening of the planned cells
  /// Highest cost a shortened segment may cross: low, so corners of the shortened path keep the
  /// robot clear of walls (with the default inflation, 40 is about 0.38 m from an obstacle).
  int shorten_max_cost = 40;
  bool ant_colony = false;  ///< ant-colony refinement after shortening (slower)
  AntColonyOptions ant_colony_options;
  DynamicWindowOptions dwa;
  double tolerance_xy = 0.15;   ///< [m] default goal position tolerance
  double tolerance_yaw = 0.25;  ///< [rad] default goal heading tolerance
  double lookahead = 0.8;       ///< [m] the dynamic window heads for the path this far ahead
  double replan_period = 2.0;   ///< [s] replan this often while driving; 0 = only when blocked
  double stuck_time = 8.0;      ///< [s] no progress for this long: recover
  double stuck_progress = 0.1;  ///< [m] of remaining distance that counts as progress
  double turn_gain = 1.5;       ///< [1/s] turning in place towards the goal heading
  /// [m] a blocked start cell (the robot brushing an inflated obstacle) plans from the nearest
  /// passable cell within this radius.
  double start_search_radius = 0.5;
  RecoveryOptions recovery;

  template <class V>
  void visit(V& v) {
    v("planner", planner, "global grid search (A* or Dijkstra)");
    v("shorten", shorten, "line-of-sight shortening of the planned path");
    v("shorten_max_cost", shorten_max_cost, "highest cost (0-252) a shortened segment may cross");
    v("ant_colony", ant_colony, "ant-colony refinement of the shortened path");
    v("ant_colony_options", ant_colony_options, "the ant-colony refinement");
    v("dwa", dwa, "dynamic window local planner");
    v("tolerance_xy", tolerance_xy, "[m] default goal position tolerance");
    v("tolerance_yaw", tolerance_yaw, "[rad] default goal heading tolerance");
    v("lookahead", lookahead, "[m] distance along the path the local planner heads for");
    v("replan_period", replan_period, "[s] replanning period while driving; 0 = when blocked");
    v("stuck_time", stuck_time, "[s] time without progress before a recovery");
    v("stuck_progress", stuck_progress, "[m] decrease of the remaining distance that is progress");
    v("turn_gain", turn_gain, "[1/s] gain of the final turn to the goal heading");
    v("start_search_radius", start_search_radius,
      "[m] search radius for a passable start cell when the robot's cell is blocked");
    v("recovery", recovery, "recovery behaviours");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

enum class NavState { kIdle, kDriving, kTurning, kRecovering, kReached, kFailed, kRefused };
constexpr std::array<std::pair<const char*, NavState>, 7> optionNames(NavState) {
  return {{{"idle", NavState::kIdle},
           {"driving", NavState::kDriving},
           {"turning", NavState::kTurning},
           {"recovering", NavState::kRecovering},
           {"reached", NavState::kReached},
           {"failed", NavState::kFailed},
           {"refused", NavState::kRefused}}};
}
std::string_view stateName(NavState s);
inline bool isFinal(NavState s) {
  return s == NavState::kReached || s == NavState::kFailed || s == NavState::kRefused;
}

struct NavCommand {
  Velocity velocity;  ///< for the next period; (0, 0) when idle or final
  NavState state = NavState::kIdle;
  std::string reason;             ///< why refused/failed, which recovery runs
  double distance_remaining = 0;  ///< [m] along the path (straight line before the first plan)
  bool replanned = false;         ///< a new path was made this period
  bool clear_obstacles = false;   ///< the caller should clear its obstacle layer (a recovery)
};

struct NavigatorStats {
  int plans = 0, plan_failures = 0, recoveries = 0, dwa_failures = 0;
  int landmark_plans = 0;  ///< plans whose A* had landmark bounds
  double plan_ms_total = 0, plan_ms_max = 0;
};

class Navigator {
 public:
  /// Throws std::invalid_argument for bad options.
  explicit Navigator(const NavigatorOptions& options = {});

  /// Takes a new goal (replacing the current one), or refuses it: "" when taken, else the reason
  /// (off the map, on an obstacle, non-finite); a refused goal leaves the state kRefused.
  /// Tolerances <= 0 or NaN take the defaults; an infinite yaw tolerance ignores the heading.
  std::string setGoal(const Pose2& goal, const Costmap& costmap, double tolerance_xy = 0,
                      double tolerance_yaw = 0);
  /// Landmark bounds for A* (GridPlanner::setLandmarks); nullptr: none.
  void setLandmarks(std::shared_ptr<const LandmarkBounds> landmarks) {
    planner_.setLandmarks(std::move(landmarks));
  }
  const std::shared_ptr<const LandmarkBounds>& landmarks() const { return planner_.landmarks(); }

  /// Drops the goal: idle, zero velocity.
  void cancel();

  /// One control period at time `now` [s]. Non-finite pose or velocity: zero command, state kept.
  NavCommand step(double now, const Pose2& pose, const Velocity& current, const Costmap& costmap,
                  const DistanceField& obstacles);

  NavState state() const { return state_; }
  const std::optional<Pose2>& goal() const { return goal_; }
  /// The current global path (map-frame waypoints, start … goal); empty before a plan.
  const std::vector<Eigen::Vector2d>& path() const { return path_; }
  const NavigatorStats& stats() const { return stats_; }
  const NavigatorOptions& options() const { return options_; }

  /// Whether the following steps keep every sampled arc of the dynamic window (for display; it
  /// costs a rollout of each sample). Off by default.
  void setKeepArcs(bool keep) { keep_arcs_ = keep; }
  bool keepArcs() const { return keep_arcs_; }
  /// The dynamic window's result in the last step() (map frame; with `arcs` when kept), or
  /// nullptr when that step did not run it (no goal, turning at the goal, recovering, bad input).
  const DynamicWindowResult* lastWindow() const { return has_window_ ? &window_ : nullptr; }

 private:
  bool plan(const Pose2& pose, const Costmap& costmap, std::string* why);
  bool pathBlocked(const Costmap& costmap) const;
  double remaining(const Pose2& pose) const;
  Eigen::Vector2d lookaheadPoint(const Pose2& pose);
  NavCommand startRecovery(double now, const Pose2& pose, const DistanceField& obstacles,
                           const std::string& why);
  NavCommand recover(double now, const Pose2& pose, const DistanceField& obstacles);
  NavCommand fail(const std::string& why);

  NavigatorOptions options_;
  GridPlanner planner_;
  DynamicWindow dwa_;
  std::optional<Pose2> goal_;
  double tolerance_xy_ = 0, tolerance_yaw_ = 0;
  NavState state_ = NavState::kIdle;
  std::string reason_;
  std::vector<Eigen::Vector2d> path_;
  std::size_t progress_index_ = 0;  ///< path segment the robot is on
  double last_plan_time_ = -1e300;
  bool need_plan_ = true;
  // Progress watch: the best remaining distance and when it last improved.
  double best_remaining_ = 0, best_time_ = 0;
  // Recovery in progress: kind (0 rotate, 1 back up), start pose and time.
  int attempts_ = 0, recovery_kind_ = 0;
  Pose2 recovery_start_;
  double recovery_turned_ = 0, recovery_start_time_ = 0;
  double last_theta_ = 0;
  NavigatorStats stats_;
  bool keep_arcs_ = false, has_window_ = false;
  DynamicWindowResult window_;  ///< the last step's, valid when has_window_
};

}  // namespace tessera::navigation
