// NavigationActor ("navigator"): drives the robot to goals on a known map — a thin adapter over
// Navigator (docs/algorithms.md#navigation-loop) that keeps the costmaps up to date from the
// sensors and sends velocity commands to the base.
//
// Costmaps: the static layer is a map file (PGM+YAML, map_server format; a file that fails to load
// is a ConfigError naming it) or, with map_file empty, the latest OccupancyGrid on `map` (a new
// map replaces the static layer and, unless it has another size, keeps the obstacle layer; with
// `bounds` every map is pasted into one fixed costmap, for a SLAM map that grows; that costmap
// is all unknown until the first map, so the robot can drive on what its sensors see). The obstacle
// layer keeps what
// the laser (scan, at laser_height) and, with use_depth, a depth camera (rgbd: 3D points within
// the robot's height band, so a table top the laser passes under blocks the cells beneath it)
// see now. The planning costmap (static + obstacles, inflated) is rebuilt at costmap_hz; the
// dynamic window's obstacle distances come from a rolling window of local_size around the robot,
// rebuilt every control period. With `landmarks` > 0 each static map also gets landmark bounds
// for A* (landmark_bounds.hpp), built from the static layer (unknown counted free, inflated), so
// they hold while obstacles only add cost; a growing SLAM map should leave them off (0), since
// each new map rebuilds them (a few whole-map searches, in the map's handler: ~5 s on 4 M cells);
// a map equal to the last one keeps them.
//
// Poses: the robot's map pose is the newest `pose` (message type pose_message: a localiser's
// PoseStamped, or the simulator's ground truth) moved on by the odometry since its stamp, so
// commands use 50 Hz odometry between 10 Hz localisation updates. Sensor data is placed with the
// map pose at its own stamp (odometry interpolated).
//
// Subscribes (local names; remap in the profile):
//   pose      pose_message type  keep_latest(pose_queue): base_link in the map frame
//   odom      msg::Odometry      keep_latest(odom_queue): base_link in odom + its twist (the
//                                current velocity the dynamic window starts from)
//   scan      msg::LaserScan     keep_latest(scan_queue), with use_scan
//   rgbd      msg::RgbdFrame     keep_latest(1), with use_depth: depth 16UC1 or 32FC1
//   goal      msg::NavGoal       reliable: a new goal replaces the current one
//   map       msg::OccupancyGrid keep_latest(1), only without map_file
// Publishes:
//   cmd_vel     msg::Twist      every control period (1 / control_hz): (0, 0) when idle, when a
//                               goal ends, when localisation is stale (no pose for
//                               pose_timeout_s) and instead of any non-finite command
//   nav_status  msg::NavStatus  on every change of state or goal and every status_period_s
//   path        msg::Path       the global path after every (re)plan, frame_id
//   costmap     msg::OccupancyGrid  with publish_costmap: the planning costmap after each rebuild
//                               that changed it (cells or geometry), frame_id, values as ROS
//                               costmap_2d publishes them: free 0, cost 1-252 -> 1-98, inscribed
//                               99, lethal 100, unknown -1
//   local_plan  msg::LocalPlan  at most local_plan_hz while a goal is driven: the control
//                               period's dynamic window, every sampled arc (map frame), each cut
//                               to local_plan_points poses evenly spaced along it; when the
//                               goal ends, one plan without arcs (chosen -1)
// Timing: all on the runtime clock (simulated in the simulator). Bad input (non-finite poses,
// malformed scans or depth images, goals in another frame) is counted by kind and skipped.
#pragma once

#include <tessera/msg/image.capnp.h>
#include <tessera/msg/navigation.capnp.h>
#include <tessera/geometry/mount3d.hpp>
#include <tessera/geometry/pose2.hpp>
#include <tessera/geometry/pose_history.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/navigation/costmap.hpp>
#include <tessera/navigation/landmark_bounds.hpp>
#include <tessera/navigation/navigator.hpp>
#include <tessera/navigation/obstacle_layer.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <Eigen/Geometry>

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace tessera::navigation {

struct NavigationActorOptions {
  NavigatorOptions navigator;
  std::string map_file;
  std::vector<double> bounds;
  double bounds_resolution = 0.05;
  int landmarks = kDefaultLandmarks;  ///< A* landmark bounds per static map (8 · landmarks bytes
                                      ///< per cell); 0: off
  StaticLayerOptions static_layer;
  InflationOptions inflation;
  ObstacleLayerOptions obstacles;
  bool use_scan = true;
  double laser_height = 0.25;
  bool use_depth = false;
  int depth_stride = 4;
  Mount3D depth_camera{0.1, 0.0, 1.0, 0.0, 0.15, 0.0};
  std::string pose_message = "pose_stamped";
  double control_hz = 20;
  double costmap_hz = 2;
  double local_size = 6.0;
  double pose_timeout_s = 1.0;
  double status_period_s = 1.0;
  std::string frame_id = "map";
  int pose_queue = 16;
  int odom_queue = 64;
  int scan_queue = 4;
  int pose_history = 256;
  bool publish_costmap = true;
  double local_plan_hz = 5;
  int local_plan_points = 16;

  template <class V>
  void visit(V& v) {
    v("navigator", navigator, "planning, the dynamic window, goal tolerances and recoveries");
    v("map_file", map_file, "static map YAML (ROS map_server format); empty: the 'map' topic");
    v("bounds", bounds,
      "[x0, y0, x1, y1] metres: a fixed costmap the map is pasted into (a growing SLAM map; "
      "outside it unknown); empty: the map's own extent");
    v("bounds_resolution", bounds_resolution,
      "[m/cell] of the fixed costmap with bounds; it exists (all unknown) before any map");
    v("landmarks", landmarks,
      "landmark bounds for A* built on each static map (0-16; 8 bytes per cell each); 0: off, "
      "for a map that keeps growing");
    v("static_layer", static_layer, "how map occupancy becomes cost");
    v("inflation", inflation, "inflation around obstacles (the robot's size)");
    v("obstacles", obstacles, "the obstacle layer: ranges and the robot's height band");
    v("use_scan", use_scan, "mark and clear obstacles with the laser ('scan')");
    v("laser_height", laser_height, "[m] height of the laser's plane above the floor");
    v("use_depth", use_depth, "mark and clear obstacles with a depth camera ('rgbd')");
    v("depth_stride", depth_stride, "use every n-th depth pixel in both directions");
    v("depth_camera", depth_camera, "the depth camera's mount on base_link (on the floor)");
    v("pose_message", pose_message,
      "message type on 'pose': pose_stamped (a localiser) | ground_truth | odometry");
    v("control_hz", control_hz, "[Hz] control rate: dynamic window and cmd_vel");
    v("costmap_hz", costmap_hz, "[Hz] rebuild rate of the inflated planning costmap");
    v("local_size", local_size, "[m] side of the rolling window the dynamic window sees");
    v("pose_timeout_s", pose_timeout_s, "[s] no pose for this long: stop the base");
    v("status_period_s", status_period_s, "[s] nav_status period while a goal is active");
    v("frame_id", frame_id, "the map frame");
    v("pose_queue", pose_queue, "pose mailbox size (keep-latest)");
    v("odom_queue", odom_queue, "odometry mailbox size (keep-latest)");
    v("scan_queue", scan_queue, "scan mailbox size (keep-latest)");
    v("pose_history", pose_history, "odometry poses remembered to place sensor data");
    v("publish_costmap", publish_costmap,
      "publish the planning costmap on 'costmap' after each rebuild that changed it");
    v("local_plan_hz", local_plan_hz,
      "[Hz] highest rate of 'local_plan' (the dynamic window's arcs) while driving; 0: off");
    v("local_plan_points", local_plan_points,
      "points per arc in 'local_plan' (>= 2; first and last kept, the rest evenly spaced)");
  }
};

class NavigationActor final : public Actor {
 public:
  /// Throws ConfigError naming the option, or the map file that cannot be loaded.
  explicit NavigationActor(NavigationActorOptions options);
  ~NavigationActor() override;

  void configure(ActorContext& ctx) override;
  /// Goals by outcome, plans, recoveries, stale-localisation stops, control and costmap CPU
  /// (ms per call, share of one core over the run's clock), paths, costmaps and local plans
  /// published, bad input by kind.
  void summarize(Summary& out) const override;

  const Navigator& navigator() const { return navigator_; }
  /// The current planning costmap (empty before a map).
  const Costmap& costmap() const { return planning_; }

 private:
  void onPose(Nanos stamp, const Pose2& pose);
  void onOdom(const Message<msg::Odometry>& m);
  void onScan(const Message<msg::LaserScan>& m);
  void onDepth(const Message<msg::RgbdFrame>& m);
  void onGoal(const Message<msg::NavGoal>& m);
  void onMap(const Message<msg::OccupancyGrid>& m);
  void useMap(const grid::OccupancyMap& map);
  void buildLandmarks();  ///< for the current static layer, when options_.landmarks > 0
  void tick();
  void rebuildCostmap();
  void publishCommand(const Velocity& v);
  void publishStatus(bool force);
  void publishPath();
  void publishCostmap();  ///< planning_, unless equal to the last published
  void publishLocalPlan(Nanos stamp, const DynamicWindowResult& window);
  /// The map pose at `stamp` (the newest localisation moved by odometry), if known.
  std::optional<Pose2> mapPoseAt(Nanos stamp) const;
  void bad(const std::string& kind, const std::string& what);

  NavigationActorOptions options_;
  Navigator navigator_;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::Twist> cmd_pub_;
  Publisher<msg::NavStatus> status_pub_;
  Publisher<msg::Path> path_pub_;
  Publisher<msg::OccupancyGrid> costmap_pub_;
  Publisher<msg::LocalPlan> local_plan_pub_;

  Costmap static_;             // the static layer's costs
  Costmap combined_;           // static + obstacles, before inflation
  Costmap planning_;           // combined, inflated: what the planner searches
  Costmap published_costmap_;  // the last planning costmap published (empty: none yet)
  std::optional<Nanos> last_local_plan_;
  bool local_plan_shown_ = false;  ///< the last local plan had arcs
  std::optional<ObstacleLayer> obstacles_;
  bool obstacles_dirty_ = true;
  Nanos last_costmap_ = 0;
  Eigen::Isometry3d camera_to_base_ = Eigen::Isometry3d::Identity();

  // Localisation: the newest map pose and its stamp; odometry history for moving it on.
  std::optional<std::pair<Nanos, Pose2>> pose_;
  Nanos pose_received_ = 0;
  PoseHistory odom_;
  std::optional<std::pair<Nanos, Pose2>> odom_latest_;
  Velocity velocity_;

  // Goals.
  struct PendingGoal {
    std::uint64_t id = 0;
    Pose2 pose;
    double tolerance_xy = 0, tolerance_yaw = 0;
  };
  std::optional<PendingGoal> pending_;
  std::uint64_t goal_id_ = 0;
  NavState last_state_ = NavState::kIdle;
  std::string last_reason_;
  double distance_remaining_ = 0;
  Nanos last_status_ = 0;
  bool stale_ = false;
  bool outcome_counted_ = true;  // the current goal's end is in the counts

  // Figures for the summary.
  std::uint64_t goals_ = 0, reached_ = 0, failed_ = 0, refused_ = 0, stale_stops_ = 0;
  std::uint64_t ticks_ = 0, costmap_builds_ = 0, scans_ = 0, depth_frames_ = 0, maps_ = 0;
  std::uint64_t nonfinite_commands_ = 0, paths_published_ = 0;
  std::uint64_t costmaps_published_ = 0, local_plans_published_ = 0;
  double control_cpu_ms_ = 0, control_cpu_max_ms_ = 0, costmap_cpu_ms_ = 0, sensor_cpu_ms_ = 0;
  double landmarks_ms_ = 0;
  std::uint64_t landmark_builds_ = 0;
  Costmap landmark_reference_;  ///< what the navigator's landmark bounds were built on
  Nanos first_tick_ = -1, last_tick_ = 0;
  std::map<std::string, std::uint64_t> bad_;

  // Sensor buffers kept between messages.
  std::vector<Eigen::Vector2d> scan_ends_;
  std::vector<std::uint8_t> scan_no_return_;
  std::vector<Eigen::Vector3d> depth_points_;
};

}  // namespace tessera::navigation
