// SimulatorActor ("simulator"): drives a differential-drive robot along a route in a 2D world and
// publishes what its sensors would see. A finite source: it calls finished() once every lap of
// the route is driven and publishes nothing after that.
//
// Publishes (local topic names):
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
// bias at stops). The base follows the route follower's commands under `base` acceleration
// limits (none by default).
//
// Frames: map = world frame of the World (origin at its lower-left corner); odom coincides with
// map at the start pose. Option errors throw ConfigError from the constructor.
#pragma once

#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
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
  SimulatorActor(const SimulatorActor&) = delete;
  SimulatorActor& operator=(const SimulatorActor&) = delete;

  void configure(ActorContext& ctx) override;
  /// route_length_m, sim_time_s, scans_published, odom_published, imu_published and
  /// wheel_ticks_published (when enabled, with gyro_bias_final_rad_s), distance_travelled_m,
  /// odom_drift_m / odom_heading_drift_rad (final odometry minus truth), route_completed (0/1),
  /// wall_contacts (steps whose true position was inside a wall).
  void summarize(Summary& out) const override;

  const World& world() const { return world_; }
  /// The route being driven (given, or the world's default), one lap.
  const Route& route() const { return route_; }

 private:
  void tick();
  void publishGroundTruth(Nanos stamp);
  void publishOdometry(Nanos stamp);
  void publishScan(Nanos stamp);
  void publishImu(Nanos stamp);
  void publishWheelTicks(Nanos stamp);

  SimulatorOptions options_;
  World world_;
  Route route_;
  std::optional<LaserModel> laser_;  // points into world_
  std::optional<RouteFollower> follower_;
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
};

}  // namespace tessera::sim
