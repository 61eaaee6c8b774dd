#include <tessera/sim/simulator_actor.hpp>

#include <tessera/messages/views.hpp>
#include <tessera/runtime/registry.hpp>

#include "option_checks.hpp"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <stdexcept>

namespace tessera::sim {

namespace {

using detail::str;

constexpr detail::OptionErrors kErrors("simulator");

// How far beyond the body's radius the collision check looks [m]: min_clearance_m is capped
// there.
constexpr double kClearanceMargin = 0.5;

}  // namespace

SimulatorActor::SimulatorActor(SimulatorOptions options)
    : SimulatorActor(options, kErrors.loadWorld(options.world, options.world_resolution)) {}

SimulatorActor::SimulatorActor(SimulatorOptions options, World world)
    : options_(std::move(options)), world_(std::move(world)) {
  const auto& o = options_;

  // Rates: exact integer periods, so every stamp is a whole number of steps.
  if (o.step_hz <= 0) kErrors.fail("step_hz", "must be positive, got " + str(o.step_hz));
  if (kNanosPerSecond % o.step_hz != 0)
    kErrors.fail("step_hz", str(o.step_hz) +
                                " Hz has no whole-nanosecond period; use a divisor of 1e9 such "
                                "as 50, 100, 200, 250, 500 or 1000");
  auto divisor = [&](const char* key, int hz) -> std::uint64_t {
    if (hz <= 0) kErrors.fail(key, "must be positive, got " + str(hz));
    if (hz > o.step_hz || o.step_hz % hz != 0)
      kErrors.fail(key, str(hz) + " Hz must divide step_hz (" + str(o.step_hz) + " Hz)");
    return static_cast<std::uint64_t>(o.step_hz / hz);
  };
  odom_every_ = divisor("odom_hz", o.odom_hz);
  scan_every_ = divisor("scan_hz", o.scan_hz);
  // Only when on: the defaults need not divide the step rate of a profile without them.
  if (o.gyro.enabled) imu_every_ = divisor("gyro.rate_hz", o.gyro.rate_hz);
  if (o.encoders.enabled) ticks_every_ = divisor("encoders.rate_hz", o.encoders.rate_hz);
  period_ = kNanosPerSecond / o.step_hz;
  dt_ = nanosToSeconds(period_);

  if (o.laps < 1) kErrors.fail("laps", "must be at least 1, got " + str(o.laps));
  kErrors.check(o.follower.check(), "follower");
  kErrors.check(o.odometry.check(), "odometry");
  kErrors.check(o.laser.check(), "laser");
  kErrors.check(o.base.check(), "base");
  kErrors.check(o.gyro.check(), "gyro");
  kErrors.check(o.encoders.check(), "encoders");
  if (!(o.start_pause_s >= 0 && o.start_pause_s <= 1e6))
    kErrors.fail("start_pause_s", "must be in [0, 1e6] s, got " + str(o.start_pause_s));
  pause_steps_ = static_cast<std::uint64_t>(std::llround(o.start_pause_s * o.step_hz));
  if (o.gyro.enabled) {
    gyro_.emplace(o.gyro);
    gyro_rng_ = detail::seededStream(o.seed, detail::NoiseStream::kGyro);
  }
  if (o.encoders.enabled) {
    encoders_.emplace(o.encoders);
    encoder_rng_ = detail::seededStream(o.seed, detail::NoiseStream::kEncoders);
  }
  laser_.emplace(world_, o.laser);
  laser_rng_ = detail::seededStream(o.seed, detail::NoiseStream::kLaser);

  if (o.drive != "route" && o.drive != "commands")
    kErrors.fail("drive", "must be 'route' or 'commands', got '" + o.drive + "'");
  commands_ = o.drive == "commands";
  if (!(o.command_timeout_s > 0 && o.command_timeout_s <= 1e6))  // false for NaN
    kErrors.fail("command_timeout_s", "must be in (0, 1e6] s, got " + str(o.command_timeout_s));
  command_timeout_ = secondsToNanos(o.command_timeout_s);
  kErrors.check(o.footprint.check(), "footprint");

  // A pose option [x, y, theta] in free space (else a ConfigError naming it).
  const auto poseOption = [&](const char* key, const std::vector<double>& v) {
    std::string value = "[";
    for (std::size_t i = 0; i < v.size(); ++i) value += (i ? ", " : "") + str(v[i]);
    value += "]";
    if (v.size() != 3) kErrors.fail(key, "must be 3 numbers [x, y, theta], got " + value);
    if (!std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); }))
      kErrors.fail(key, "must be finite, got " + value);
    if (world_.blocked(Eigen::Vector2d(v[0], v[1])))
      kErrors.fail(key, value + " is in a wall or outside world '" + world_.name() + "' (" +
                            str(world_.widthMeters()) + " m x " + str(world_.heightMeters()) +
                            " m)");
    return Pose2{v[0], v[1], normalizeAngle(v[2])};
  };
  if (!(std::isfinite(o.kidnap_at_s) && o.kidnap_at_s >= 0))
    kErrors.fail("kidnap_at_s", "must be finite and >= 0 s, got " + str(o.kidnap_at_s));
  if (!std::isfinite(o.kidnap_turn))
    kErrors.fail("kidnap_turn", "must be finite, got " + str(o.kidnap_turn));
  if (o.kidnap_at_s > 0) {
    if (commands_) {
      kidnap_pose_ = poseOption("kidnap_pose", o.kidnap_pose);
      if (o.kidnap_route_m >= 0 || o.kidnap_turn != 0)
        kErrors.fail("kidnap_route_m",
                     "is only used with drive: route (commands mode uses kidnap_pose)");
    } else {
      if (!o.kidnap_pose.empty())
        kErrors.fail("kidnap_pose",
                     "is only used with drive: commands (route mode uses kidnap_route_m)");
      if (!(std::isfinite(o.kidnap_route_m) && o.kidnap_route_m >= 0))
        kErrors.fail("kidnap_route_m",
                     "must be the distance along the route [m] the kidnapping puts the robot, "
                     ">= 0, got " +
                         str(o.kidnap_route_m));
    }
    kidnap_step_ = std::max<std::uint64_t>(
        1, static_cast<std::uint64_t>(std::llround(o.kidnap_at_s * o.step_hz)));
  } else if (!o.kidnap_pose.empty()) {
    kErrors.fail("kidnap_pose", "is only used with kidnap_at_s > 0");
  } else if (o.kidnap_route_m >= 0 || o.kidnap_turn != 0) {
    kErrors.fail(o.kidnap_route_m >= 0 ? "kidnap_route_m" : "kidnap_turn",
                 "is only used with kidnap_at_s > 0");
  }

  if (!o.start_pose.empty()) {
    if (!commands_)
      kErrors.fail("start_pose",
                   "is only used with drive: commands (a route starts on its first "
                   "waypoint)");
    start_ = poseOption("start_pose", o.start_pose);
  } else {
    // Route: given, or the world's own (in commands mode only for its start pose).
    route_ = kErrors.routeOrDefault(world_, o.route);
    const bool open = (route_.back() - route_.front()).norm() > 1e-6;
    try {
      checkRoute(world_, route_, /*closed=*/o.laps > 1 && open);
      follower_.emplace(route_, o.follower, o.laps);
    } catch (const std::invalid_argument& e) {
      kErrors.fail("route", e.what());  // the follower's speeds and the laps were checked above
    }
    start_ = follower_->startPose();
    if (commands_) follower_.reset();
    if (follower_ && kidnap_step_ > 0 && options_.kidnap_route_m > follower_->totalLength())
      kErrors.fail("kidnap_route_m", "is beyond the route's end (" + str(follower_->totalLength()) +
                                         " m), got " + str(options_.kidnap_route_m));
  }
  robot_.emplace(start_, o.odometry, o.seed, o.base);
}

void SimulatorActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  scan_pub_ = ctx.advertise<msg::LaserScan>("scan");
  odom_pub_ = ctx.advertise<msg::Odometry>("odom");
  gt_pub_ = ctx.advertise<msg::GroundTruthPose>("ground_truth");
  if (gyro_) imu_pub_ = ctx.advertise<msg::ImuSample>("imu");
  if (encoders_) ticks_pub_ = ctx.advertise<msg::WheelTicks>("wheel_ticks");
  if (commands_) {
    // Only the newest command matters: a stale one queued behind it would be followed late.
    ctx.subscribe<msg::Twist>("cmd_vel", MailboxPolicy::keepLatest(1),
                              [this](const Message<msg::Twist>& cmd) { onCommand(cmd); });
  } else {
    ctx.declareFiniteSource();  // ends once every lap is driven
  }
  ctx.addTimer(
      period_, [this] { tick(); }, 0);
}

void SimulatorActor::onCommand(const Message<msg::Twist>& cmd) {
  ++commands_received_;
  const auto twist = cmd->getTwist();
  const double v = twist.getVx(), omega = twist.getOmega();
  if (!std::isfinite(v) || !std::isfinite(omega)) {
    ++bad_commands_;  // never reaches the base; the previous command ages towards the watchdog
    return;
  }
  const FollowerConfig& limits = options_.follower;
  command_ = {std::clamp(v, -limits.v_max, limits.v_max),
              std::clamp(omega, -limits.w_max, limits.w_max)};
  if (command_.v != v || command_.omega != omega) ++clamped_commands_;
  command_time_ = ctx_->now();
  have_command_ = true;
}

Twist SimulatorActor::currentCommand() {
  const bool fresh = have_command_ && ctx_->now() - command_time_ <= command_timeout_;
  if (following_command_ && !fresh) ++watchdog_stops_;
  following_command_ = fresh;
  return fresh ? command_ : Twist{};
}

void SimulatorActor::checkCollision() {
  const double radius = options_.footprint.radius;
  const Eigen::Vector2d p = robot_->truePose().translation();
  const double clearance =
      footprintClearance(world_, p, options_.footprint.height, radius + kClearanceMargin);
  min_clearance_ = step_ == 0 ? clearance - radius : std::min(min_clearance_, clearance - radius);
  const bool contact = clearance < radius;
  if (contact) {
    ++collision_steps_;
    if (!in_contact_) {
      ++collisions_;
      // t: time since the start (the step's), also under a wall clock.
      std::cerr << "simulator: collision at t=" << static_cast<double>(step_) * dt_
                << " s, x=" << p.x() << " y=" << p.y() << " (clearance " << clearance << " m)\n";
    }
  }
  in_contact_ = contact;
}

void SimulatorActor::tick() {
  if (finished_) return;
  if (step_ > 0) {
    // Standing still during the start pause; then the follower or the commands drive.
    Twist cmd;
    if (step_ > pause_steps_)
      cmd = commands_ ? currentCommand() : follower_->command(robot_->truePose(), dt_);
    robot_->step(cmd, dt_);
    if (step_ == kidnap_step_) {
      if (follower_) {
        kidnap_pose_ = follower_->jumpTo(options_.kidnap_route_m);
        kidnap_pose_.theta = normalizeAngle(kidnap_pose_.theta + options_.kidnap_turn);
      }
      robot_->teleport(kidnap_pose_);
      kidnapped_ = true;
      std::cerr << "[simulator] kidnapped: the robot is carried to (" << kidnap_pose_.x << ", "
                << kidnap_pose_.y << ", " << kidnap_pose_.theta << ")\n";
    }
    const Twist& vel = robot_->velocity();  // the command under the base's limits
    const Eigen::Vector2d inc = robot_->lastOdometryIncrement();
    const Eigen::Vector2d sd = robot_->odometry().incrementStd(vel.v * dt_, vel.omega * dt_);
    if (encoders_) encoders_->move(vel.v * dt_, vel.omega * dt_, encoder_rng_);
    imu_rotation_ += vel.omega * dt_;
    imu_centripetal_ += vel.v * vel.omega * dt_;
    odom_sum_d_ += inc[0];
    odom_sum_t_ += inc[1];
    odom_var_d_ += sd[0] * sd[0];
    odom_var_t_ += sd[1] * sd[1];
    ++odom_steps_;
    if (world_.blocked(robot_->truePose().translation())) ++wall_contacts_;
  }
  checkCollision();

  const Nanos stamp = ctx_->now();
  const bool odom_due = step_ % odom_every_ == 0;
  const bool scan_due = step_ % scan_every_ == 0;
  const bool ticks_due = encoders_ && step_ % ticks_every_ == 0;
  if (odom_due || scan_due || ticks_due) publishGroundTruth(stamp);
  if (odom_due) publishOdometry(stamp);
  if (gyro_ && step_ % imu_every_ == 0) publishImu(stamp);
  if (ticks_due) publishWheelTicks(stamp);
  if (scan_due) {
    publishScan(stamp);
    if (follower_) ctx_->reportProgress(follower_->progress());
  }
  ++step_;

  if (follower_ && follower_->done()) {
    finished_ = true;
    ctx_->reportProgress(1.0);
    ctx_->finished();
  }
}

void SimulatorActor::publishGroundTruth(Nanos stamp) {
  auto loan = gt_pub_.loan();
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, "map", gt_pub_.nextSeq());
  const Pose2& p = robot_->truePose();
  writePose(b.initPose(), tessera::Pose2{p.x, p.y, p.theta});
  b.setChildFrameId("base_link");
  gt_pub_.publish(std::move(loan));
}

void SimulatorActor::publishOdometry(Nanos stamp) {
  auto loan = odom_pub_.loan();
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, "odom", odom_pub_.nextSeq());
  b.setChildFrameId("base_link");
  const Pose2& p = robot_->odometry().pose();
  const Eigen::Matrix3d cov = robot_->odometry().covariance();
  writePose(b.initPose(), tessera::Pose2{p.x, p.y, p.theta}, &cov);

  // Twist: the mean of the noisy wheel velocities since the last message, with the variance of
  // that mean (a differential drive has no lateral velocity).
  auto twist = b.initTwist();
  auto tc = b.initTwistCovariance(9);
  for (unsigned i = 0; i < 9; ++i) tc.set(i, 0.0);
  if (odom_steps_ > 0) {
    const double span = static_cast<double>(odom_steps_) * dt_;
    twist.setVx(odom_sum_d_ / span);
    twist.setOmega(odom_sum_t_ / span);
    tc.set(0, odom_var_d_ / (span * span));
    tc.set(8, odom_var_t_ / (span * span));
  }
  odom_sum_d_ = odom_sum_t_ = odom_var_d_ = odom_var_t_ = 0;
  odom_steps_ = 0;
  odom_pub_.publish(std::move(loan));
  ++odom_published_;
}

void SimulatorActor::publishImu(Nanos stamp) {
  // The first sample (step 0) covers an interval of the robot at rest before the start.
  const double interval = static_cast<double>(imu_every_) * dt_;
  const double v1 = robot_->velocity().v;
  const ImuReading r =
      gyro_->sample(imu_rotation_, imu_v0_, v1, imu_centripetal_ / interval, interval, gyro_rng_);
  imu_rotation_ = imu_centripetal_ = 0;
  imu_v0_ = v1;
  auto loan = imu_pub_.loan();
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, "imu", imu_pub_.nextSeq());
  b.setAngularVelocityX(r.angular_velocity.x());
  b.setAngularVelocityY(r.angular_velocity.y());
  b.setAngularVelocityZ(r.angular_velocity.z());
  b.setLinearAccelerationX(r.linear_acceleration.x());
  b.setLinearAccelerationY(r.linear_acceleration.y());
  b.setLinearAccelerationZ(r.linear_acceleration.z());
  imu_pub_.publish(std::move(loan));
  ++imu_published_;
}

void SimulatorActor::publishWheelTicks(Nanos stamp) {
  const EncoderOptions& o = encoders_->options();
  auto loan = ticks_pub_.loan();
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, "base_link", ticks_pub_.nextSeq());
  b.setLeft(encoders_->leftTicks());
  b.setRight(encoders_->rightTicks());
  b.setTicksPerRevolution(o.ticks_per_revolution);
  b.setWheelRadius(o.wheel_radius);  // nominal: the true wheels differ by the configured errors
  b.setWheelBase(o.wheel_base);
  ticks_pub_.publish(std::move(loan));
  ++ticks_published_;
}

void SimulatorActor::publishScan(Nanos stamp) {
  const LaserConfig& c = laser_->config();
  auto loan = scan_pub_.loan(static_cast<std::size_t>(c.beams) * sizeof(float) + 256);
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, "laser", scan_pub_.nextSeq());
  b.setAngleMin(static_cast<float>(c.angleMin()));
  b.setAngleIncrement(static_cast<float>(c.angleIncrement()));
  b.setRangeMin(static_cast<float>(c.range_min));
  b.setRangeMax(static_cast<float>(c.range_max));
  b.setScanTimeS(0.0f);  // the simulated sweep is instantaneous
  b.setMountX(static_cast<float>(c.mount.x));
  b.setMountY(static_cast<float>(c.mount.y));
  b.setMountTheta(static_cast<float>(c.mount.theta));
  laser_->scan(robot_->truePose(), laser_rng_,
               mutableView<float>(b.initRanges(static_cast<unsigned>(c.beams))));
  scan_pub_.publish(std::move(loan));
  ++scans_published_;
}

void SimulatorActor::summarize(Summary& out) const {
  const Pose2& truth = robot_->truePose();
  const Pose2& odom = robot_->odometry().pose();
  if (follower_) {
    out["route_length_m"] = follower_->totalLength();
    out["route_completed"] = static_cast<std::int64_t>(follower_->done() ? 1 : 0);
  } else {
    out["commands_received"] = commands_received_;
    out["bad_commands"] = bad_commands_;
    out["clamped_commands"] = clamped_commands_;
    out["watchdog_stops"] = watchdog_stops_;
  }
  if (kidnap_step_ > 0) out["kidnapped"] = kidnapped_ ? 1 : 0;
  out["sim_time_s"] = step_ > 0 ? static_cast<double>(step_ - 1) * dt_ : 0.0;
  out["scans_published"] = scans_published_;
  out["odom_published"] = odom_published_;
  if (gyro_) {
    out["imu_published"] = imu_published_;
    out["gyro_bias_final_rad_s"] = gyro_->bias();
  }
  if (encoders_) out["wheel_ticks_published"] = ticks_published_;
  out["distance_travelled_m"] = robot_->distanceTravelled();
  out["odom_drift_m"] = (odom.translation() - truth.translation()).norm();
  out["odom_heading_drift_rad"] = std::abs(normalizeAngle(odom.theta - truth.theta));
  out["wall_contacts"] = wall_contacts_;
  out["collisions"] = collisions_;
  out["collision_steps"] = collision_steps_;
  out["min_clearance_m"] = min_clearance_;
}

TESSERA_REGISTER_ACTOR("simulator", SimulatorActor, SimulatorOptions,
                       "2D world simulator: drives a route or follows cmd_vel, publishes laser "
                       "scans, noisy odometry and ground truth, counts collisions");

}  // namespace tessera::sim
