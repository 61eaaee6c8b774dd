// GoalSequencerActor ("goal_sequencer"): sends a navigation stack its goals one after another —
// from a goals file (scripted runs) or drawn at random among the places the robot can reach —
// waits for each to end (nav_status), and measures the run: outcome, time to goal, distance
// driven against the shortest path. A finite source: the run ends after the last goal.
//
// Goals file: one goal per line, "x y theta [tolerance_xy [tolerance_yaw]]" in the map frame
// [m, m, rad]; '#' starts a comment; blank lines are skipped. A line that does not parse (or has
// non-finite numbers) is a ConfigError naming the file and line.
// Random goals (random > 0) are drawn on the map on `map`: cells at least `clearance` from every
// occupied or unknown cell, connected to the robot's start through such cells, at least
// min_distance from the previous goal, with a uniform heading. In the simulator `map` is the true
// footprint map (walls and furniture in the robot's height band), so every goal is reachable.
// The shortest path for a goal is the length of the line-of-sight-shortened grid path through
// that same clearance region from where the robot was when the goal was sent.
//
// Subscribes: pose (pose_message type; base_link in the map frame: the truth in the simulator),
//             nav_status (msg::NavStatus, reliable), map (msg::OccupancyGrid, keep_latest(1);
//             only with random > 0).
// Publishes:  goal (msg::NavGoal, id = 1, 2, … in order).
// Output: goals_csv in the run's folder: one row per goal with its outcome and figures.
// Goals, the map and the poses are in one frame; with map_origin the goals are sent in the
// navigator's frame (map_origin⁻¹ ⊕ goal), e.g. a SLAM map anchored at the start pose.
#pragma once

#include <tessera/msg/navigation.capnp.h>
#include <tessera/geometry/pose2.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/navigation/costmap.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace tessera::navigation {

struct GoalSequencerOptions {
  std::string goals_file;
  int random = 0;
  std::uint64_t seed = 1;
  double clearance = 0.45;
  double min_distance = 3.0;
  double tolerance_xy = 0;
  double tolerance_yaw = 0;
  double goal_timeout_s = 120;
  double start_delay_s = 2.0;
  std::string pose_message = "ground_truth";
  std::string goals_csv = "goals.csv";
  std::string frame_id = "map";
  std::vector<double> map_origin;

  template <class V>
  void visit(V& v) {
    v("goals_file", goals_file, "goals, 'x y theta [tol_xy [tol_yaw]]' per line");
    v("random", random, "number of random reachable goals (instead of a goals file)");
    v("seed", seed, "random seed of the random goals");
    v("clearance", clearance, "[m] random goals and shortest paths keep this far from obstacles");
    v("min_distance", min_distance, "[m] a random goal is at least this far from the previous");
    v("tolerance_xy", tolerance_xy, "[m] goal position tolerance; 0: the navigator's default");
    v("tolerance_yaw", tolerance_yaw, "[rad] goal heading tolerance; 0: the navigator's default");
    v("goal_timeout_s", goal_timeout_s, "[s] a goal not ended by then counts as timed out");
    v("start_delay_s", start_delay_s, "[s] wait before the first goal (localisation settles)");
    v("pose_message", pose_message,
      "message type on 'pose': ground_truth | pose_stamped | odometry");
    v("goals_csv", goals_csv, "per-goal results in the output folder; empty: none");
    v("frame_id", frame_id, "the map frame");
    v("map_origin", map_origin,
      "[x, y, theta]: the navigator's map frame in the frame of this actor's map and poses (a "
      "SLAM map starts at the robot's start pose); goals are sent in that frame. Empty: the same");
  }
};

/// One goal line of a goals file. Throws std::invalid_argument for a malformed line.
struct GoalSpec {
  Pose2 pose;
  double tolerance_xy = 0, tolerance_yaw = 0;
};
std::vector<GoalSpec> readGoalsFile(const std::string& path);

/// Cells of `map` whose centre is at least `clearance` from every lethal or unknown cell,
/// connected to `start` through such cells (8-neighbours); empty when start is not such a cell.
/// Also gives the costmap it used (kInscribed within clearance), for shortestPathLength().
std::vector<Eigen::Vector2i> reachableCells(const Costmap& map, double clearance,
                                            const Eigen::Vector2d& start, Costmap* eroded);
/// [m] length of the shortest path from a to b through the eroded costmap's free cells
/// (grid path shortened by line of sight); NaN when there is none.
double shortestPathLength(const Costmap& eroded, const Eigen::Vector2d& a,
                          const Eigen::Vector2d& b);

class GoalSequencerActor final : public Actor {
 public:
  /// Throws ConfigError for bad options or a goals file that cannot be read (naming the line).
  explicit GoalSequencerActor(GoalSequencerOptions options);

  void configure(ActorContext& ctx) override;
  void stop() override;
  /// goals, reached, failed, refused, timed_out, mean_time_to_goal_s (reached goals),
  /// path_length_ratio (mean over reached goals of driven / shortest), driven_m.
  void summarize(Summary& out) const override;

  struct Result {
    std::uint64_t id = 0;
    GoalSpec goal;
    std::string outcome;  // reached | failed | refused | timed_out | pending
    std::string reason;
    double time_s = 0, driven_m = 0, shortest_m = 0;
  };
  const std::vector<Result>& results() const { return results_; }

 private:
  void onPose(Nanos stamp, const Pose2& pose);
  void onStatus(const Message<msg::NavStatus>& m);
  void onMap(const Message<msg::OccupancyGrid>& m);
  void tick();
  bool drawGoals();
  void sendNext();
  void finish(const std::string& outcome, const std::string& reason);

  GoalSequencerOptions options_;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::NavGoal> goal_pub_;
  std::vector<GoalSpec> goals_;
  bool goals_ready_ = false;
  std::optional<Costmap> map_;
  Costmap eroded_;
  std::mt19937_64 rng_;
  std::optional<Pose2> pose_;
  Pose2 map_origin_;  // the navigator's frame in ours
  std::size_t next_ = 0;
  bool active_ = false, done_ = false;
  Nanos sent_at_ = 0, start_ = -1;
  std::vector<Result> results_;
};

}  // namespace tessera::navigation
