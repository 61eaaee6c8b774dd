#include <tessera/sim/landmark_simulator_actor.hpp>

#include <tessera/runtime/registry.hpp>

#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace tessera::sim {

namespace {

constexpr double kDeg = std::numbers::pi / 180;

[[noreturn]] void fail(const std::string& key, const std::string& what) {
  throw ConfigError("landmark_simulator: option '" + key + "': " + what);
}

template <typename T>
std::string str(const T& v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

World loadWorld(const LandmarkSimulatorOptions& o) {
  try {
    return World::fromSpec(o.world, o.world_resolution);
  } catch (const std::invalid_argument& e) {
    fail("world_resolution", e.what());
  } catch (const std::exception& e) {
    fail("world", e.what());
  }
}

std::mt19937_64 sensorRng(std::uint64_t seed) {
  std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                    0x6c6d6b73u};  // "lmks"
  return std::mt19937_64(seq);
}

}  // namespace

LandmarkSimulatorActor::LandmarkSimulatorActor(LandmarkSimulatorOptions options)
    : options_(std::move(options)),
      world_(loadWorld(options_)),
      sensor_rng_(sensorRng(options_.seed)) {
  const auto& o = options_;
  auto positive = [](const char* key, double v) {
    if (!(v > 0) || !std::isfinite(v)) fail(key, "must be positive, got " + str(v));
  };
  auto nonNegative = [](const char* key, double v) {
    if (!(v >= 0) || !std::isfinite(v)) fail(key, "must be >= 0, got " + str(v));
  };
  positive("step_s", o.step_s);
  period_ = static_cast<Nanos>(std::llround(o.step_s * 1e9));
  if (period_ < 1 || std::abs(static_cast<double>(period_) * 1e-9 - o.step_s) > 1e-12)
    fail("step_s", str(o.step_s) + " s is not a whole number of nanoseconds");
  dt_ = nanosToSeconds(period_);
  positive("speed", o.speed);
  positive("wheelbase", o.wheelbase);
  if (!(o.max_steer_deg > 0 && o.max_steer_deg < 90))
    fail("max_steer_deg", "must be in (0, 90), got " + str(o.max_steer_deg));
  positive("steer_rate_deg", o.steer_rate_deg);
  nonNegative("sigma_speed", o.sigma_speed);
  nonNegative("sigma_steer_deg", o.sigma_steer_deg);
  positive("waypoint_tolerance", o.waypoint_tolerance);
  if (o.observe_every < 1) fail("observe_every", "must be at least 1, got " + str(o.observe_every));
  if (!(o.landmark_fov_deg > 0 && o.landmark_fov_deg <= 360))
    fail("landmark_fov_deg", "must be in (0, 360], got " + str(o.landmark_fov_deg));
  nonNegative("landmark_min_range", o.landmark_min_range);
  if (!(o.landmark_max_range > o.landmark_min_range) || !std::isfinite(o.landmark_max_range))
    fail("landmark_max_range",
         "must be finite and above landmark_min_range, got " + str(o.landmark_max_range));
  nonNegative("landmark_range_noise", o.landmark_range_noise);
  nonNegative("landmark_bearing_noise_deg", o.landmark_bearing_noise_deg);
  if (o.landmark_mount.size() != 3)
    fail("landmark_mount", "needs 3 values [x, y, theta], got " + str(o.landmark_mount.size()));
  nonNegative("max_sim_time_s", o.max_sim_time_s);

  // Route and landmarks: given, or the world's.
  if (o.route.empty()) {
    route_ = world_.defaultRoute();
    if (route_.empty())
      fail("route", "world '" + world_.name() + "' has no default route; give waypoints");
  } else {
    for (const auto& p : o.route) route_.emplace_back(p[0], p[1]);
  }
  try {
    checkRoute(world_, route_);
    steering_.emplace(route_, o.waypoint_tolerance);
  } catch (const std::invalid_argument& e) {
    fail("route", e.what());
  }
  std::vector<PointLandmark> landmarks;
  if (o.landmarks.empty()) {
    landmarks = world_.landmarks();
    if (landmarks.empty())
      fail("landmarks", "world '" + world_.name() + "' has no landmarks; give landmarks");
  } else {
    for (std::size_t i = 0; i < o.landmarks.size(); ++i)
      landmarks.push_back({static_cast<int>(i), {o.landmarks[i][0], o.landmarks[i][1]}});
  }

  LandmarkSensorConfig sc;
  sc.fov = o.landmark_fov_deg * kDeg;
  sc.max_range = o.landmark_max_range;
  sc.min_range = o.landmark_min_range;
  sc.range_noise = o.landmark_range_noise;
  sc.bearing_noise = o.landmark_bearing_noise_deg * kDeg;
  sc.with_ids = o.landmark_ids;
  sc.occlusion = o.landmark_occlusion;
  sc.mount = {o.landmark_mount[0], o.landmark_mount[1], o.landmark_mount[2]};
  try {
    sensor_.emplace(std::move(landmarks), sc, &world_);
  } catch (const std::invalid_argument& e) {
    fail(o.landmarks.empty() ? "world" : "landmarks", e.what());  // the numbers were checked
  }

  CarLikeConfig car;
  car.wheelbase = o.wheelbase;
  car.max_steer = o.max_steer_deg * kDeg;
  car.steer_rate = o.steer_rate_deg * kDeg;
  car.sigma_speed = o.sigma_speed;
  car.sigma_steer = o.sigma_steer_deg * kDeg;
  robot_.emplace(steering_->startPose(), car, o.seed);

  const double limit_s =
      o.max_sim_time_s > 0 ? o.max_sim_time_s : 3 * steering_->totalLength() / o.speed + 60;
  max_steps_ = static_cast<std::uint64_t>(std::ceil(limit_s / dt_));
}

void LandmarkSimulatorActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.declareFiniteSource();
  gt_pub_ = ctx.advertise<msg::GroundTruthPose>("ground_truth");
  odom_pub_ = ctx.advertise<msg::Odometry>("odom");
  control_pub_ = ctx.advertise<msg::DriveControl>("control");
  scan_pub_ = ctx.advertise<msg::LandmarkScan>("landmarks");
  map_pub_ = ctx.advertise<msg::LandmarkMap>("landmark_map");
  ctx.addTimer(
      period_, [this] { tick(); }, 0);
}

void LandmarkSimulatorActor::publishLandmarkMap(Nanos stamp) {
  const auto& lms = sensor_->landmarks();
  auto loan = map_pub_.loan(lms.size() * 64 + 256);
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, "map", map_pub_.nextSeq());
  auto list = b.initLandmarks(static_cast<unsigned>(lms.size()));
  for (unsigned i = 0; i < lms.size(); ++i) {
    list[i].setId(lms[i].id);
    list[i].setX(lms[i].position.x());
    list[i].setY(lms[i].position.y());
  }
  map_pub_.publish(std::move(loan));
}

void LandmarkSimulatorActor::tick() {
  if (finished_) return;
  const Nanos stamp = ctx_->now();
  if (step_ == 0) publishLandmarkMap(stamp);

  const Pose2& truth = robot_->truePose();
  {
    auto loan = gt_pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), stamp, "map", gt_pub_.nextSeq());
    writePose(b.initPose(), tessera::Pose2{truth.x, truth.y, truth.theta});
    b.setChildFrameId("base_link");
    gt_pub_.publish(std::move(loan));
  }
  {
    auto loan = odom_pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), stamp, "odom", odom_pub_.nextSeq());
    b.setChildFrameId("base_link");
    const Pose2& p = robot_->odometryPose();
    writePose(b.initPose(), tessera::Pose2{p.x, p.y, p.theta});
    if (step_ > 0) {
      // The reported control of the last step, as a velocity of the reference point.
      const DriveCommand& u = robot_->lastReportedControl();
      b.initTwist().setVx(u.speed * std::cos(u.steer));
      b.getTwist().setVy(u.speed * std::sin(u.steer));
      b.getTwist().setOmega(u.speed * std::sin(u.steer) / options_.wheelbase);
    }
    odom_pub_.publish(std::move(loan));
  }
  if (step_ % static_cast<std::uint64_t>(options_.observe_every) == 0) {
    const auto obs = sensor_->observe(truth, sensor_rng_);
    auto loan = scan_pub_.loan(obs.size() * 64 + 256);
    auto b = loan.builder();
    setHeader(b.initHeader(), stamp, "landmark_sensor", scan_pub_.nextSeq());
    const Pose2& m = sensor_->config().mount;
    b.setMountX(m.x);
    b.setMountY(m.y);
    b.setMountTheta(m.theta);
    auto list = b.initObservations(static_cast<unsigned>(obs.size()));
    for (unsigned i = 0; i < obs.size(); ++i) {
      list[i].setId(obs[i].id);
      list[i].setRange(obs[i].range);
      list[i].setBearing(obs[i].bearing);
      list[i].setRangeStd(sensor_->config().range_noise);
      list[i].setBearingStd(sensor_->config().bearing_noise);
      seen_.insert(obs[i].true_id);
    }
    scan_pub_.publish(std::move(loan));
    observations_ += static_cast<std::int64_t>(obs.size());
    ++scans_published_;
    ctx_->reportProgress(steering_->progress());
  }

  const double demand = steering_->demand(truth);
  if (steering_->done() || step_ >= max_steps_) {
    finished_ = true;
    ctx_->reportProgress(1.0);
    ctx_->finished();
    return;
  }
  robot_->step(options_.speed, demand, dt_);
  {
    const DriveCommand& u = robot_->lastReportedControl();
    auto loan = control_pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), stamp, "base_link", control_pub_.nextSeq());
    b.setSpeed(u.speed);
    b.setSteering(u.steer);
    b.setWheelbase(options_.wheelbase);
    b.setTurnRate(0);
    b.setDtS(dt_);
    control_pub_.publish(std::move(loan));
  }
  ++step_;
}

void LandmarkSimulatorActor::summarize(Summary& out) const {
  const Pose2& truth = robot_->truePose();
  const Pose2& odom = robot_->odometryPose();
  out["route_length_m"] = steering_->totalLength();
  out["sim_time_s"] = static_cast<double>(step_) * dt_;
  out["waypoints_reached"] = static_cast<std::int64_t>(steering_->reached());
  out["waypoint_count"] = static_cast<std::int64_t>(steering_->waypointCount());
  out["route_completed"] = static_cast<std::int64_t>(steering_->done() ? 1 : 0);
  out["distance_travelled_m"] = robot_->distanceTravelled();
  out["odom_drift_m"] = (odom.translation() - truth.translation()).norm();
  out["odom_heading_drift_rad"] = std::abs(normalizeAngle(odom.theta - truth.theta));
  out["landmark_count"] = static_cast<std::int64_t>(sensor_->landmarks().size());
  out["landmarks_seen"] = static_cast<std::int64_t>(seen_.size());
  out["observations"] = observations_;
  out["scans_published"] = scans_published_;
}

TESSERA_REGISTER_ACTOR(
    "landmark_simulator", LandmarkSimulatorActor, LandmarkSimulatorOptions,
    "car-like robot among point landmarks (seed 004): range-bearing "
    "observations, noisy controls and odometry, ground truth, true landmark map");

}  // namespace tessera::sim
