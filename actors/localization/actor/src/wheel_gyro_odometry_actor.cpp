// wheel_gyro_odometry actor: wheel ticks -> tick intervals, waiting for the gyro to cover them
// -> WheelGyroEkf steps -> odom.
#include <tessera/localization/wheel_gyro_odometry_actor.hpp>

#include <tessera/messages/geometry.hpp>
#include <tessera/runtime/registry.hpp>

#include <cmath>
#include <cstdlib>
#include <iostream>
#include <numbers>
#include <stdexcept>
#include <utility>

namespace tessera::localization {

namespace {

constexpr const char* kName = "wheel_gyro_odometry";
constexpr std::uint64_t kReportedPerKind = 5;  // stderr lines per kind of bad input

bool finitePose(const Pose2& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.theta);
}

}  // namespace

WheelGyroOdometryActor::WheelGyroOdometryActor(WheelGyroOdometryOptions options)
    : options_(std::move(options)) {
  const auto& o = options_;
  const auto fail = [](const std::string& key, const std::string& rule) {
    throw ConfigError(std::string(kName) + ": option '" + key + "' " + rule);
  };
  try {
    o.ekf.validate();
  } catch (const std::invalid_argument& e) {
    fail("ekf", e.what());
  }
  if (!(std::isfinite(o.max_wheel_speed) && o.max_wheel_speed > 0))
    fail("max_wheel_speed", "must be finite and > 0");
  if (!(std::isfinite(o.gyro_timeout_s) && o.gyro_timeout_s >= 0))
    fail("gyro_timeout_s", "must be finite and >= 0");
  if (o.ticks_queue < 1) fail("ticks_queue", "must be at least 1");
  if (o.imu_queue < 1) fail("imu_queue", "must be at least 1");
  if (!finitePose(o.start)) fail("start", "must be finite");
  metres_per_tick_ = o.ekf.metres_per_tick;
  wheel_base_ = o.ekf.wheel_base;
}

void WheelGyroOdometryActor::configure(ActorContext& ctx) {
  ctx.subscribe<msg::WheelTicks>(
      "wheel_ticks", MailboxPolicy::reliable(static_cast<std::size_t>(options_.ticks_queue)),
      [this](const Message<msg::WheelTicks>& m) { onTicks(m); });
  if (options_.use_gyro)
    ctx.subscribe<msg::ImuSample>(
        "imu", MailboxPolicy::reliable(static_cast<std::size_t>(options_.imu_queue)),
        [this](const Message<msg::ImuSample>& m) { onImu(m); });
  odom_pub_ = ctx.advertise<msg::Odometry>("odom");
}

void WheelGyroOdometryActor::bad(std::map<std::string, std::uint64_t>& counts,
                                 const std::string& kind, const std::string& what) {
  if (++counts[kind] <= kReportedPerKind)
    std::cerr << "[" << kName << "] " << what << "; skipped"
              << (counts[kind] == kReportedPerKind ? " (further ones counted only)" : "") << "\n";
}

void WheelGyroOdometryActor::onImu(const Message<msg::ImuSample>& m) {
  ++imu_received_;
  const Nanos stamp = m->getHeader().getStampNs();
  const double rate = m->getAngularVelocityZ();
  const std::string what = "imu sample at " + std::to_string(stamp) + " ns";
  if (!std::isfinite(rate)) return bad(imu_bad_, "nan", what + ": yaw rate is not finite");
  if (!gyro_.add(stamp, rate))
    return bad(imu_bad_, "out_of_order",
               what + ": not after the previous sample (" +
                   std::to_string(gyro_.lastStamp().value_or(0)) + " ns)");
  drain(false);
}

void WheelGyroOdometryActor::onTicks(const Message<msg::WheelTicks>& m) {
  ++ticks_received_;
  const Nanos stamp = m->getHeader().getStampNs();
  const std::int64_t left = m->getLeft(), right = m->getRight();
  const std::string what = "wheel ticks at " + std::to_string(stamp) + " ns";

  const double tpr = m->getTicksPerRevolution(), radius = m->getWheelRadius();
  const double base = m->getWheelBase();
  const bool calibration_ok = std::isfinite(tpr) && tpr > 0 && std::isfinite(radius) &&
                              radius > 0 && std::isfinite(base) && base > 0;
  if (options_.calibration_from_message && !calibration_ok)
    return bad(ticks_bad_, "calibration",
               what + ": ticks_per_revolution " + std::to_string(tpr) + ", wheel_radius " +
                   std::to_string(radius) + ", wheel_base " + std::to_string(base) +
                   " (all must be finite and > 0)");
  if (calibration_ok) {
    const double mpt = 2 * std::numbers::pi * radius / tpr;
    if (msg_wheel_base_ == 0) {
      msg_metres_per_tick_ = mpt;
      msg_wheel_base_ = base;
    } else if (mpt != msg_metres_per_tick_ || base != msg_wheel_base_) {
      // Kept: the filter's state is in terms of the first calibration.
      if (++calibration_changes_ == 1)
        std::cerr << "[" << kName << "] " << what
                  << ": the calibration changed; keeping the first one\n";
    }
  }

  if (!last_stamp_) {  // the first ticks: the counters' baseline and the filter's start
    if (options_.calibration_from_message) {
      metres_per_tick_ = msg_metres_per_tick_;
      wheel_base_ = msg_wheel_base_;
    }
    WheelGyroEkfOptions ekf = options_.ekf;
    ekf.metres_per_tick = metres_per_tick_;
    ekf.wheel_base = wheel_base_;
    ekf_.emplace(ekf, options_.start);
    last_stamp_ = stamp;
    last_left_ = left;
    last_right_ = right;
    return;
  }
  if (stamp < *last_stamp_)
    return bad(ticks_bad_, "out_of_order",
               what + ": before the previous ticks (" + std::to_string(*last_stamp_) + " ns)");
  if (stamp == *last_stamp_)
    return bad(ticks_bad_, "zero_dt", what + ": same stamp as the previous ticks");

  // Wrapping differences are well defined in unsigned arithmetic.
  const auto diff = [](std::int64_t a, std::int64_t b) {
    return static_cast<std::int64_t>(static_cast<std::uint64_t>(a) - static_cast<std::uint64_t>(b));
  };
  const std::int64_t dl = diff(left, last_left_), dr = diff(right, last_right_);
  const double dt = nanosToSeconds(stamp - *last_stamp_);
  const double max_ticks = options_.max_wheel_speed * dt / metres_per_tick_;
  if (static_cast<double>(std::llabs(dl)) > max_ticks ||
      static_cast<double>(std::llabs(dr)) > max_ticks) {
    // A counter reset or wrap: the interval's motion is unknown. Re-baseline, and let the gyro
    // coverage restart at this stamp.
    bad(ticks_bad_, "jump",
        what + ": increments (" + std::to_string(dl) + ", " + std::to_string(dr) +
            ") exceed max_wheel_speed; counters re-baselined");
  } else {
    waiting_.push_back({*last_stamp_, stamp, dl, dr});
  }
  last_stamp_ = stamp;
  last_left_ = left;
  last_right_ = right;
  drain(false);
}

void WheelGyroOdometryActor::drain(bool flush) {
  while (!waiting_.empty()) {
    const Interval in = waiting_.front();
    std::optional<double> gyro_angle;
    if (options_.use_gyro) {
      gyro_angle = gyro_.integrate(in.t0, in.t1);
      if (!gyro_angle) {
        const bool timed_out =
            last_stamp_ && nanosToSeconds(*last_stamp_ - in.t1) > options_.gyro_timeout_s;
        if (!flush && !timed_out) return;  // wait for the gyro to cover it
      }
    }
    waiting_.pop_front();
    stepInterval(in, gyro_angle);
  }
}

void WheelGyroOdometryActor::stepInterval(const Interval& in, std::optional<double> gyro_angle) {
  const double dt = nanosToSeconds(in.t1 - in.t0);
  const Pose2 before = ekf_->pose();
  if (!ekf_->step(static_cast<double>(in.dl), static_cast<double>(in.dr), dt, gyro_angle) ||
      !finitePose(ekf_->pose())) {
    ++rejected_steps_;  // cannot happen with checked input; kept visible if it does
    return;
  }
  ++steps_;
  if (gyro_angle)
    ++steps_with_gyro_;
  else if (options_.use_gyro)
    ++steps_without_gyro_;

  const Pose2 p = ekf_->pose();
  const double distance = metres_per_tick_ / 2 * static_cast<double>(in.dl + in.dr);
  const double rotation = normalizeAngle(p.theta - before.theta);
  auto loan = odom_pub_.loan();
  auto b = loan.builder();
  setHeader(b.initHeader(), in.t1, "odom", odom_pub_.nextSeq());
  b.setChildFrameId("base_link");
  const Eigen::Matrix3d cov = ekf_->poseCovariance();
  writePose(b.initPose(), p, &cov);
  auto twist = b.initTwist();
  twist.setVx(distance / dt);
  twist.setVy(0);
  twist.setOmega(rotation / dt);
  // Twist variances from the model's step noise: distance (σ_D D)², rotation from the gyro's
  // angle noise when it was used, else from the wheels'.
  const WheelGyroEkfOptions& o = options_.ekf;
  const double var_d = std::pow(o.sigma_distance * distance, 2);
  const double var_t = gyro_angle ? o.gyro_noise * o.gyro_noise * dt
                                  : std::pow(o.sigma_rotation * rotation, 2) +
                                        std::pow(o.sigma_rotation_per_metre * distance, 2);
  auto tc = b.initTwistCovariance(9);
  for (unsigned i = 0; i < 9; ++i) tc.set(i, 0.0);
  tc.set(0, var_d / (dt * dt));
  tc.set(8, var_t / (dt * dt));
  odom_pub_.publish(std::move(loan));
}

void WheelGyroOdometryActor::stop() {
  if (ekf_) drain(true);
}

void WheelGyroOdometryActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["ticks_received"] = i64(ticks_received_);
  out["imu_received"] = i64(imu_received_);
  out["steps"] = i64(steps_);
  out["steps_with_gyro"] = i64(steps_with_gyro_);
  out["steps_without_gyro"] = i64(steps_without_gyro_);
  if (rejected_steps_ > 0) out["steps_rejected"] = i64(rejected_steps_);
  const auto counts = [&](const std::string& prefix,
                          const std::map<std::string, std::uint64_t>& m) {
    std::uint64_t total = 0;
    for (const auto& [kind, n] : m) {
      out[prefix + "_" + kind] = i64(n);
      total += n;
    }
    out[prefix] = i64(total);
  };
  counts("ticks_bad", ticks_bad_);
  counts("imu_bad", imu_bad_);
  out["calibration_changes"] = i64(calibration_changes_);
  if (ekf_) {
    const Pose2 p = ekf_->pose();
    out["final_x_m"] = p.x;
    out["final_y_m"] = p.y;
    out["final_theta_rad"] = p.theta;
    out["gyro_bias_rad_s"] = ekf_->gyroBias();
    out["metres_per_tick"] = metres_per_tick_;
    out["wheel_base_m"] = wheel_base_;
  }
}

TESSERA_REGISTER_ACTOR("wheel_gyro_odometry", WheelGyroOdometryActor, WheelGyroOdometryOptions,
                       "wheel encoder ticks + gyro -> EKF odometry (odom)");

}  // namespace tessera::localization
