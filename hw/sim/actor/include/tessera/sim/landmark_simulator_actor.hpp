// LandmarkSimulatorActor ("landmark_simulator"): the seed 004 experiment
// (docs/algorithms.md#landmark-slam). A car-like robot (car_like.hpp) steers through waypoints at
// constant speed in a world of point landmarks and observes them with a range-bearing sensor
// (landmark_sensor.hpp). A finite source: it calls finished() once the last waypoint is reached (or
// after max_sim_time_s).
//
// A separate actor rather than a mode of "simulator": the kinematics (car-like, fixed speed,
// steering-rate limit), the step (dT = 0.03 s is not a whole number of Hz) and the outputs differ.
//
// Publishes (local topic names):
//   ground_truth  msg::GroundTruthPose  frame "map", child "base_link"; every step
//   odom          msg::Odometry         frame "odom"; dead reckoning of the noisy controls
//   control       msg::DriveControl     the noisy (speed, steering) applied over [stamp, +dtS]
//   landmarks     msg::LandmarkScan     frame "landmark_sensor"; every observe_every steps
//   landmark_map  msg::LandmarkMap      frame "map"; the true landmarks, once, at time 0
//
// Timing: step k has time k * step_s. At step k the actor publishes the state at that time
// (ground truth, odometry, a landmark scan when due), then the control for [t_k, t_k+1] and
// integrates it, so a filter predicts with control k from its state at t_k. Option errors throw
// ConfigError from the constructor.
#pragma once

#include <tessera/msg/landmark.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/sim/car_like.hpp>
#include <tessera/sim/landmark_sensor.hpp>
#include <tessera/sim/world.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <vector>

namespace tessera::sim {

struct LandmarkSimulatorOptions {
  std::string world = "builtin:landmarks";
  double world_resolution = 0.05;
  std::vector<std::array<double, 2>> route;
  std::vector<std::array<double, 2>> landmarks;
  double step_s = 0.03;
  double speed = 3.0;
  CarLikeConfig car;
  double waypoint_tolerance = 1.0;
  int observe_every = 8;
  LandmarkSensorConfig sensor;
  double max_sim_time_s = 0;
  std::uint64_t seed = 1;

  template <class V>
  void visit(V& v) {
    v("world", world,
      "'builtin:landmarks' (seed 004) or another built-in / PGM/PNG world (walls only matter "
      "with sensor.occlusion)");
    v("world_resolution", world_resolution, "metres per pixel of an image world");
    v("route", route, "waypoints [[x, y], ...] [m]; empty = the world's default route");
    v("landmarks", landmarks, "landmarks [[x, y], ...] [m], ids 0, 1, ...; empty = the world's");
    v("step_s", step_s, "control and integration step dT [s]; a whole number of nanoseconds");
    v("speed", speed, "constant speed V [m/s]");
    v("car", car, "the car-like robot: geometry, steering limits, control noise");
    v("waypoint_tolerance", waypoint_tolerance, "a waypoint counts as reached this close [m]");
    v("observe_every", observe_every, "publish a landmark scan every this many steps");
    v("sensor", sensor, "the range-bearing landmark sensor");
    v("max_sim_time_s", max_sim_time_s,
      "give up after this much simulated time [s]; 0 = 3 x route length / speed + 60 s");
    v("seed", seed, "random seed; equal seeds give identical runs");
  }

  /// The flat keys of earlier versions, now inside the car and sensor groups (angles in
  /// radians there).
  static constexpr RenamedKey kRenamedKeys[] = {
      {"wheelbase", "car.wheelbase"},
      {"max_steer_deg", "car.max_steer"},
      {"steer_rate_deg", "car.steer_rate"},
      {"sigma_speed", "car.sigma_speed"},
      {"sigma_steer_deg", "car.sigma_steer"},
      {"landmark_fov_deg", "sensor.fov"},
      {"landmark_max_range", "sensor.max_range"},
      {"landmark_min_range", "sensor.min_range"},
      {"landmark_range_noise", "sensor.range_noise"},
      {"landmark_bearing_noise_deg", "sensor.bearing_noise"},
      {"landmark_ids", "sensor.with_ids"},
      {"landmark_occlusion", "sensor.occlusion"},
      {"landmark_mount", "sensor.mount.x and sensor.mount.y and sensor.mount.theta"},
  };
};

class LandmarkSimulatorActor final : public Actor {
 public:
  explicit LandmarkSimulatorActor(LandmarkSimulatorOptions options);
  LandmarkSimulatorActor(const LandmarkSimulatorActor&) = delete;
  LandmarkSimulatorActor& operator=(const LandmarkSimulatorActor&) = delete;

  void configure(ActorContext& ctx) override;
  /// route_length_m, sim_time_s, waypoints_reached, waypoint_count, route_completed (0/1),
  /// distance_travelled_m, odom_drift_m, odom_heading_drift_rad, landmark_count, landmarks_seen
  /// (distinct), observations, scans_published.
  void summarize(Summary& out) const override;

  const World& world() const { return world_; }
  const Route& route() const { return route_; }
  const LandmarkSensor& sensor() const { return *sensor_; }

 private:
  void tick();
  void publishLandmarkMap(Nanos stamp);

  LandmarkSimulatorOptions options_;
  World world_;
  Route route_;
  std::optional<LandmarkSensor> sensor_;
  std::optional<WaypointSteering> steering_;
  std::optional<CarLikeRobot> robot_;
  std::mt19937_64 sensor_rng_;

  ActorContext* ctx_ = nullptr;
  Publisher<msg::GroundTruthPose> gt_pub_;
  Publisher<msg::Odometry> odom_pub_;
  Publisher<msg::DriveControl> control_pub_;
  Publisher<msg::LandmarkScan> scan_pub_;
  Publisher<msg::LandmarkMap> map_pub_;

  Nanos period_ = 0;
  double dt_ = 0;
  std::uint64_t step_ = 0, max_steps_ = 0;
  bool finished_ = false;
  std::set<int> seen_;
  std::int64_t observations_ = 0, scans_published_ = 0;
};

}  // namespace tessera::sim
