#include <tessera/sim/landmark_simulator_actor.hpp>

#include <tessera/runtime/registry.hpp>

#include "option_checks.hpp"

#include <cmath>
#include <stdexcept>

namespace tessera::sim {

namespace {

constexpr detail::OptionErrors kErrors("landmark_simulator");

}  // namespace

LandmarkSimulatorActor::LandmarkSimulatorActor(LandmarkSimulatorOptions options)
    : options_(std::move(options)),
      world_(kErrors.loadWorld(options_.world, options_.world_resolution)),
      sensor_rng_(detail::seededStream(options_.seed, detail::NoiseStream::kLandmarkSensor)) {
  const auto& o = options_;
  kErrors.check(ConfigCheck().positive("step_s", o.step_s));
  period_ = static_cast<Nanos>(std::llround(o.step_s * 1e9));
  if (period_ < 1 || std::abs(static_cast<double>(period_) * 1e-9 - o.step_s) > 1e-12)
    kErrors.fail("step_s", detail::str(o.step_s) + " s is not a whole number of nanoseconds");
  dt_ = nanosToSeconds(period_);
  kErrors.check(
      ConfigCheck()
          .positive("speed", o.speed)
          .positive("waypoint_tolerance", o.waypoint_tolerance)
          .require(o.observe_every >= 1, "observe_every", "must be at least 1", o.observe_every)
          .nonNegative("max_sim_time_s", o.max_sim_time_s));
  kErrors.check(o.car.check(), "car");
  kErrors.check(o.sensor.check(), "sensor");

  // Route and landmarks: given, or the world's.
  route_ = kErrors.routeOrDefault(world_, o.route);
  try {
    checkRoute(world_, route_);
    steering_.emplace(route_, o.waypoint_tolerance);
  } catch (const std::invalid_argument& e) {
    kErrors.fail("route", e.what());
  }
  std::vector<PointLandmark> landmarks;
  if (o.landmarks.empty()) {
    landmarks = world_.landmarks();
    if (landmarks.empty())
      kErrors.fail("landmarks", "world '" + world_.name() + "' has no landmarks; give landmarks");
  } else {
    for (std::size_t i = 0; i < o.landmarks.size(); ++i)
      landmarks.push_back({static_cast<int>(i), {o.landmarks[i][0], o.landmarks[i][1]}});
  }
  try {
    sensor_.emplace(std::move(landmarks), o.sensor, &world_);
  } catch (const std::invalid_argument& e) {
    // The sensor's numbers were checked above: the landmarks themselves are wrong.
    kErrors.fail(o.landmarks.empty() ? "world" : "landmarks", e.what());
  }
  robot_.emplace(steering_->startPose(), o.car, o.seed);

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
      b.getTwist().setOmega(u.speed * std::sin(u.steer) / options_.car.wheelbase);
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
    b.setWheelbase(options_.car.wheelbase);
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
