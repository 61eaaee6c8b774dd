// SimulatorActor ("simulator"): drives a differential-drive robot in a 2D world with 3D
// furniture and publishes what its sensors would see. Two ways to drive (`drive`):
//   route     (default) a built-in route follower drives the route (given, or the world's
//             default) `laps` times. A finite source: it calls finished() once every lap is
//             driven and publishes nothing after that.
//   commands  the robot follows velocity commands from `cmd_vel` (a navigation stack), starting
//             at `start_pose` (empty: the route's start pose). Not a finite source: the run ends
//             when another finite source finishes, at the time limit, or on Ctrl-C.
//
// Subscribes (commands mode only):
//   cmd_vel       msg::Twist            keep_latest(1); vx [m/s] and omega [rad/s] are used, vy
//                                       is ignored (a differential drive cannot move sideways).
//                                       |vx| and |omega| above follower.v_max / follower.w_max
//                                       are clamped; a command with a non-finite vx or omega is
//                                       ignored (counted). When the newest command is older
//                                       than command_timeout_s (runtime clock, from its
//                                       receipt) a watchdog commands (0, 0) until the next one.
// Publishes (local topic names), the same in both modes:
//   scan          msg::LaserScan        frame "laser"; mount pose in the message
//   odom          msg::Odometry         frame "odom", child "base_link"; noisy dead reckoning
//   ground_truth  msg::GroundTruthPose  frame "map", child "base_link"; the true pose
//   wheel_ticks   msg::WheelTicks       frame "base_link"; cumulative encoder ticks with the
//                                       nominal calibration (only with encoders.enabled)
//   imu           msg::ImuSample        frame "imu" = base_link; gyro and accelerometer, each
//                                       value the mean since the previous sample (only with
//                                       gyro.enabled)
//
// Timing: one timer at step_hz integrates the robot on simulated time. At step k (time
// k / step_hz, k = 0 being the start pose) odometry is published when k is a multiple of
// step_hz / odom_hz and a scan when k is a multiple of step_hz / scan_hz; integer step counting
// keeps the rates exact; wheel_ticks and imu likewise at encoders.rate_hz and gyro.rate_hz.
// Whenever odometry, a scan or wheel ticks are published, ground_truth is published first with
// the same stamp, so a known-pose consumer can pair every scan with its true pose exactly.
// With start_pause_s > 0 the robot stands still that long before it drives (a gyro learns its
// bias at stops; commands are not followed before then). The base follows the route follower's
// or cmd_vel's commands under `base` acceleration limits (none by default).
//
// Kidnapping (kidnap_at_s > 0): at that simulated time the true robot is carried away and
// stopped; odometry does not see it (a localiser has to notice on its own). Commands mode: to
// kidnap_pose. Route mode: to kidnap_route_m metres along the route, turned by kidnap_turn, and
// the follower drives on from there.
//
// Collisions (both modes): every step the body (`footprint`, a vertical cylinder) is checked
// against the true 3D world with footprintClearance() (collision.hpp): walls, the map border and
// furniture below the body's top. The robot is not stopped by a contact (it is counted, and each
// contact episode is reported once on stderr), so a run shows how often a planner would have hit
// something the laser cannot see.
//
// Frames: map = world frame of the World (origin at its lower-left corner); odom coincides with
// map at the start pose. Option errors throw ConfigError from the constructor.
#pragma once

#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/sim/collision.hpp>
#include <tessera/sim/ray_caster.hpp>
#include <tessera/sim/robot.hpp>
#include <tessera/sim/wheel_sensors.hpp>
#include <tessera/sim/world.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace tessera::sim {

struct SimulatorOptions {
  std::string world = "builtin:office";
  double world_resolution = 0.05;
  std::vector<std::array<double, 2>> route;
  int laps = 1;
  int step_hz = 100;
  int odom_hz = 50;
  int scan_hz = 10;
  FollowerConfig follower;
  OdometryNoise odometry;
  LaserConfig laser;
  BaseLimits base;
  GyroOptions gyro;
  EncoderOptions encoders;
  double start_pause_s = 0;
  std::uint64_t seed = 1;
  std::string drive = "route";
  double command_timeout_s = 0.5;
  std::vector<double> start_pose;
  FootprintOptions footprint;
  double kidnap_at_s = 0;
  std::vector<double> kidnap_pose;
  double kidnap_route_m = -1;
  double kidnap_turn = 0;

  template <class V>
  void visit(V& v) {
    v("world", world,
      "'builtin:office' or the path of a PGM/PNG map (dark pixels < 128 are walls, top row = "
      "highest y, relative paths from the working directory)");
    v("world_resolution", world_resolution, "metres per pixel of an image world");
    v("route", route,
      "waypoints [[x, y], ...] in metres in the map frame; empty = the world's default route");
    v("laps", laps, "times to drive the route (an open route is closed between laps)");
    v("step_hz", step_hz,
      "integration rate [Hz]; must divide 1e9 ns. Odometry noise is drawn per step, so the "
      "drift for given sigmas depends on it");
    v("odom_hz", odom_hz, "odometry rate [Hz]; must divide step_hz");
    v("scan_hz", scan_hz, "laser rate [Hz]; must divide step_hz");
    v("follower", follower, "the route follower (pure pursuit) that drives the robot");
    v("odometry", odometry, "wheel odometry noise, drawn once per step");
    v("laser", laser, "the simulated planar laser");
    v("base", base, "acceleration limits of the base's motors (0 = it follows commands at once)");
    v("gyro", gyro, "the IMU's gyro and accelerometer (off by default)");
    v("encoders", encoders, "wheel encoders and the true wheels' calibration errors (off)");
    v("start_pause_s", start_pause_s,
      "the robot stands still this long before driving [s] (a gyro learns its bias at stops)");
    v("seed", seed, "random seed; equal seeds give identical runs");
    v("drive", drive,
      "'route': the route follower drives the route (a finite source); 'commands': follow "
      "velocity commands from cmd_vel (not a finite source)");
    v("command_timeout_s", command_timeout_s,
      "commands mode: the base is stopped when the newest cmd_vel is older than this [s]");
    v("start_pose", start_pose,
      "commands mode: start pose [x, y, theta] in the map frame [m, m, rad]; empty = the "
      "route's start (its first waypoint, facing the second)");
    v("footprint", footprint,
      "the robot's body for collision checks: a vertical cylinder on the floor");
    v("kidnap_at_s", kidnap_at_s,
      "commands mode: carry the robot to kidnap_pose at this simulated time, unseen by its "
      "odometry [s]; 0 = never");
    v("kidnap_pose", kidnap_pose,
      "commands mode: where the kidnapping puts the robot: [x, y, theta] [m, m, rad]");
    v("kidnap_route_m", kidnap_route_m,
      "route mode: the kidnapping puts the robot this far along its route [m], facing along it "
      "(turned by kidnap_turn), and the route goes on from there");
    v("kidnap_turn", kidnap_turn, "route mode: the kidnapped robot's heading off the route [rad]");
  }

  /// The flat keys of earlier versions, now inside the follower, odometry and laser groups
  /// (laser.fov in radians where laser_fov_deg was in degrees).
  static constexpr RenamedKey kRenamedKeys[] = {
      {"v_max", "follower.v_max"},
      {"w_max", "follower.w_max"},
      {"sigma_d", "odometry.sigma_d"},
      {"sigma_theta", "odometry.sigma_theta"},
      {"odom_bias_d", "odometry.bias_d"},
      {"odom_bias_theta", "odometry.bias_theta"},
      {"odom_drift_theta", "odometry.drift_theta"},
      {"laser_fov_deg", "laser.fov"},
      {"laser_beams", "laser.beams"},
      {"laser_max_range", "laser.range_max"},
      {"laser_min_range", "laser.range_min"},
      {"laser_range_noise", "laser.range_noise"},
      {"laser_dropout", "laser.dropout"},
      {"laser_mount", "laser.mount.x and laser.mount.y and laser.mount.theta"},
  };
};

class SimulatorActor final : public Actor {
 public:
  /// Loads the world and checks every option and the route; throws ConfigError naming the
  /// option (and for a route, the waypoint index and coordinates).
  explicit SimulatorActor(SimulatorOptions options);
  /// The same in `world` instead of options.world (a world built in code, e.g. with furniture
  /// added; world and world_resolution are not read).
  SimulatorActor(SimulatorOptions options, World world);
  SimulatorActor(const SimulatorActor&) = delete;
  SimulatorActor& operator=(const SimulatorActor&) = delete;

  void configure(ActorContext& ctx) override;
  /// route_length_m, sim_time_s, scans_published, odom_published, imu_published and
  /// wheel_ticks_published (when enabled, with gyro_bias_final_rad_s), distance_travelled_m,
  /// odom_drift_m / odom_heading_drift_rad (final odometry minus truth), route_completed (0/1),
  /// wall_contacts (steps whose true position was inside a wall); collisions (contact episodes:
  /// steps whose footprint clearance fell below footprint.radius after one that did not),
  /// collision_steps, min_clearance_m (smallest clearance minus radius, negative = overlap).
  /// route_length_m and route_completed in route mode only; in commands mode
  /// commands_received, bad_commands (non-finite, ignored), clamped_commands and
  /// watchdog_stops (times the watchdog stopped a commanded base); in both, kidnapped (0/1)
  /// with kidnap_at_s.
  void summarize(Summary& out) const override;

  const World& world() const { return world_; }
  /// The route being driven (given, or the world's default), one lap; in commands mode the
  /// route that gave the start pose (empty with start_pose).
  const Route& route() const { return route_; }
  /// Where the robot started.
  const Pose2& startPose() const { return start_; }

 private:
  void tick();
  void onCommand(const Message<msg::Twist>& cmd);
  /// The command for this step in commands mode: the newest one, or (0, 0) when it is stale.
  Twist currentCommand();
  void checkCollision();
  void publishGroundTruth(Nanos stamp);
  void publishOdometry(Nanos stamp);
  void publishScan(Nanos stamp);
  void publishImu(Nanos stamp);
  void publishWheelTicks(Nanos stamp);

  SimulatorOptions options_;
  World world_;
  Route route_;
  std::optional<LaserModel> laser_;  // points into world_
  bool commands_ = false;
  Pose2 start_;
  std::optional<RouteFollower> follower_;  // route mode only
  std::optional<DiffDriveRobot> robot_;
  std::mt19937_64 laser_rng_;
  std::optional<Gyro> gyro_;
  std::optional<WheelEncoders> encoders_;
  std::mt19937_64 gyro_rng_, encoder_rng_;

  ActorContext* ctx_ = nullptr;
  Publisher<msg::LaserScan> scan_pub_;
  Publisher<msg::Odometry> odom_pub_;
  Publisher<msg::GroundTruthPose> gt_pub_;
  Publisher<msg::ImuSample> imu_pub_;
  Publisher<msg::WheelTicks> ticks_pub_;

  Nanos period_ = 0;
  double dt_ = 0;
  std::uint64_t odom_every_ = 1, scan_every_ = 1, imu_every_ = 1, ticks_every_ = 1;
  std::uint64_t step_ = 0, pause_steps_ = 0;
  bool finished_ = false;

  // Noisy increments since the last odometry message, for its twist.
  double odom_sum_d_ = 0, odom_sum_t_ = 0, odom_var_d_ = 0, odom_var_t_ = 0;
  std::uint64_t odom_steps_ = 0;

  // True motion since the last imu sample: rotation [rad], ∫v·ω dt [m/s], speed at that sample.
  double imu_rotation_ = 0, imu_centripetal_ = 0, imu_v0_ = 0;

  std::int64_t scans_published_ = 0, odom_published_ = 0, wall_contacts_ = 0;
  std::int64_t imu_published_ = 0, ticks_published_ = 0;

  // Commands mode: the newest accepted command, when it arrived, and whether the last step
  // followed it (to count watchdog engagements).
  Twist command_;
  Nanos command_time_ = 0, command_timeout_ = 0;
  bool have_command_ = false, following_command_ = false;
  std::int64_t commands_received_ = 0, bad_commands_ = 0, clamped_commands_ = 0;
  std::int64_t watchdog_stops_ = 0;

  std::uint64_t kidnap_step_ = 0;  // 0 = none
  Pose2 kidnap_pose_;
  bool kidnapped_ = false;

  bool in_contact_ = false;
  std::int64_t collisions_ = 0, collision_steps_ = 0;
  double min_clearance_ = 0;  // set at the first step
};

}  // namespace tessera::sim
