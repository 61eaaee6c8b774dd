#include <tessera/players/landmark_player.hpp>

#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>

namespace tessera::players {

namespace {

[[noreturn]] void fail(const std::string& key, const std::string& what) {
  throw ConfigError("landmark_player: option '" + key + "': " + what);
}

template <typename T>
std::string str(const T& v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// Longest recording played (about 3 years), far inside the int64 nanosecond range.
constexpr double kMaxSpan = 1e8;

// Dataset seconds since the first record -> nanoseconds, rounded to whole microseconds: doubles
// near 1.2e9 s carry 0.24 us of noise, which would otherwise show in the stamps.
Nanos relativeNanos(double t, double t0) {
  return static_cast<Nanos>(std::llround((t - t0) * 1e6)) * 1000;
}

// Speed along the constant-curvature arc with chord (dx, dy) and heading change dtheta.
double arcLength(double dx, double dy, double dtheta) {
  const double chord = std::copysign(std::hypot(dx, dy), dx);
  const double half = 0.5 * dtheta;
  return std::abs(half) < 1e-9 ? chord : chord * half / std::sin(half);
}

}  // namespace

LandmarkPlayerActor::LandmarkPlayerActor(LandmarkPlayerOptions options)
    : options_(std::move(options)) {
  const auto& o = options_;
  if (o.format != "mrclam" && o.format != "victoria")
    fail("format", "must be 'mrclam' or 'victoria', got '" + o.format + "'");
  if (o.path.empty()) fail("path", "is required");
  if (!(o.range_std >= 0) || !std::isfinite(o.range_std))
    fail("range_std", "must be >= 0, got " + str(o.range_std));
  if (!(o.bearing_std >= 0) || !std::isfinite(o.bearing_std))
    fail("bearing_std", "must be >= 0, got " + str(o.bearing_std));
  try {
    if (o.format == "mrclam") {
      if (o.robot < 1 || o.robot > datasets::kMrclamRobots)
        fail("robot", "must be 1.." + str(datasets::kMrclamRobots) + ", got " + str(o.robot));
      mrclam_ = datasets::readMrclam(o.path, o.robot);
      buildMrclam();
    } else {
      if (!(o.victoria_step_s > 0 && o.victoria_step_s <= 10))
        fail("victoria_step_s", "must be in (0, 10] s, got " + str(o.victoria_step_s));
      step_ = static_cast<Nanos>(std::llround(o.victoria_step_s * 1e9));
      victoria_ = datasets::readVictoriaPark(o.path);
      buildVictoria();
    }
  } catch (const io::DatasetError& e) {
    fail("path", e.what());
  }
  std::stable_sort(events_.begin(), events_.end(), [](const Event& a, const Event& b) {
    return a.time != b.time ? a.time < b.time : a.kind < b.kind;
  });
}

void LandmarkPlayerActor::buildMrclam() {
  const auto& log = *mrclam_;
  double t0 = std::numeric_limits<double>::infinity();
  if (!log.odometry.empty()) t0 = std::min(t0, log.odometry.front().time);
  if (!log.measurements.empty()) t0 = std::min(t0, log.measurements.front().time);
  if (!log.ground_truth.empty()) t0 = std::min(t0, log.ground_truth.front().time);
  if (!std::isfinite(t0))
    throw io::DatasetError(options_.path, 0,
                           "robot " + str(options_.robot) + " has no records to play");

  double t1 = t0;
  if (!log.odometry.empty()) t1 = std::max(t1, log.odometry.back().time);
  if (!log.measurements.empty()) t1 = std::max(t1, log.measurements.back().time);
  if (!log.ground_truth.empty()) t1 = std::max(t1, log.ground_truth.back().time);
  if (t1 - t0 > kMaxSpan)
    throw io::DatasetError(options_.path, 0,
                           "robot " + str(options_.robot) + "'s records span " + str(t1 - t0) +
                               " s; more than " + str(kMaxSpan) + " s is not a recording");

  events_.push_back({0, Kind::kMap, 0});
  for (std::size_t i = 0; i < log.ground_truth.size(); ++i)
    events_.push_back({relativeNanos(log.ground_truth[i].time, t0), Kind::kGroundTruth,
                       static_cast<std::uint32_t>(i)});
  for (std::size_t i = 0; i < log.odometry.size(); ++i)
    events_.push_back(
        {relativeNanos(log.odometry[i].time, t0), Kind::kControl, static_cast<std::uint32_t>(i)});
  const auto& m = log.measurements;
  for (std::size_t b = 0; b < m.size();) {
    std::size_t e = b;
    bool landmark = false, robot = false;
    while (e < m.size() && m[e].time == m[b].time) {
      (m[e].is_robot ? robot : landmark) = true;
      ++e;
    }
    const auto g = static_cast<std::uint32_t>(groups_.size());
    groups_.push_back({b, e});
    const Nanos t = relativeNanos(m[b].time, t0);
    if (landmark) events_.push_back({t, Kind::kLandmarks, g});
    if (robot) events_.push_back({t, Kind::kRobots, g});
    b = e;
  }
}

void LandmarkPlayerActor::buildVictoria() {
  const auto& log = *victoria_;
  const std::size_t poses = log.odometry.size() + 1;
  victoria_poses_.resize(poses);
  for (std::size_t k = 0; k + 1 < poses; ++k) {
    const tessera::Pose2& p = victoria_poses_[k];
    const Eigen::Vector3d& d = log.odometry[k].delta;
    const double c = std::cos(p.theta), s = std::sin(p.theta);
    victoria_poses_[k + 1] = {p.x + c * d[0] - s * d[1], p.y + s * d[0] + c * d[1],
                              normalizeAngle(p.theta + d[2])};
  }
  for (std::size_t k = 0; k < poses; ++k) {
    const Nanos t = static_cast<Nanos>(k) * step_;
    events_.push_back({t, Kind::kOdom, static_cast<std::uint32_t>(k)});
    if (k + 1 < poses) events_.push_back({t, Kind::kControl, static_cast<std::uint32_t>(k)});
  }
  victoria_order_.resize(log.observations.size());
  for (std::size_t i = 0; i < victoria_order_.size(); ++i) victoria_order_[i] = i;
  std::stable_sort(victoria_order_.begin(), victoria_order_.end(),
                   [&](std::size_t a, std::size_t b) {
                     return log.observations[a].pose_index < log.observations[b].pose_index;
                   });
  for (std::size_t b = 0; b < victoria_order_.size();) {
    const std::size_t pose = log.observations[victoria_order_[b]].pose_index;
    std::size_t e = b;
    while (e < victoria_order_.size() && log.observations[victoria_order_[e]].pose_index == pose)
      ++e;
    events_.push_back({static_cast<Nanos>(pose) * step_, Kind::kLandmarks,
                       static_cast<std::uint32_t>(groups_.size())});
    groups_.push_back({b, e});
    b = e;
  }
}

void LandmarkPlayerActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.declareFiniteSource();
  control_pub_ = ctx.advertise<msg::DriveControl>("control");
  landmarks_pub_ = ctx.advertise<msg::LandmarkScan>("landmarks");
  if (mrclam_) {
    robots_pub_ = ctx.advertise<msg::LandmarkScan>("robots");
    map_pub_ = ctx.advertise<msg::LandmarkMap>("landmark_map");
    if (!mrclam_->ground_truth.empty())
      gt_pub_ = ctx.advertise<msg::GroundTruthPose>("ground_truth");
  } else {
    odom_pub_ = ctx.advertise<msg::Odometry>("odom");
  }
  base_ = ctx.now();
  if (events_.empty()) {
    ctx.finished();
    return;
  }
  ctx.callAt(base_ + events_.front().time, [this] { play(); });
}

void LandmarkPlayerActor::play() {
  const Nanos t = events_[next_].time;
  while (next_ < events_.size() && events_[next_].time == t) publish(events_[next_++], base_ + t);
  ctx_->reportProgress(static_cast<double>(next_) / static_cast<double>(events_.size()));
  if (next_ == events_.size()) {
    ctx_->finished();
    return;
  }
  ctx_->callAt(base_ + events_[next_].time, [this] { play(); });
}

void LandmarkPlayerActor::publish(const Event& e, Nanos stamp) {
  switch (e.kind) {
    case Kind::kMap: {
      const auto& lms = mrclam_->landmarks;
      auto loan = map_pub_.loan(lms.size() * 96 + 128);
      auto b = loan.builder();
      setHeader(b.initHeader(), stamp, "map", map_pub_.nextSeq());
      auto list = b.initLandmarks(static_cast<unsigned>(lms.size()));
      for (unsigned i = 0; i < lms.size(); ++i) {
        auto l = list[i];
        l.setId(static_cast<std::int32_t>(i));
        l.setX(lms[i].x);
        l.setY(lms[i].y);
        auto c = l.initCovariance(4);
        c.set(0, lms[i].std_x * lms[i].std_x);
        c.set(1, 0.0);
        c.set(2, 0.0);
        c.set(3, lms[i].std_y * lms[i].std_y);
      }
      map_pub_.publish(std::move(loan));
      break;
    }
    case Kind::kGroundTruth: {
      const auto& p = mrclam_->ground_truth[e.index];
      auto loan = gt_pub_.loan();
      auto b = loan.builder();
      setHeader(b.initHeader(), stamp, "map", gt_pub_.nextSeq());
      writePose(b.initPose(), tessera::Pose2{p.x, p.y, p.theta});
      b.setChildFrameId("base_link");
      gt_pub_.publish(std::move(loan));
      ++ground_truth_;
      break;
    }
    case Kind::kOdom: {
      const double dt = nanosToSeconds(step_);
      auto loan = odom_pub_.loan();
      auto b = loan.builder();
      setHeader(b.initHeader(), stamp, "odom", odom_pub_.nextSeq());
      b.setChildFrameId("base_link");
      writePose(b.initPose(), victoria_poses_[e.index]);
      auto twist = b.initTwist();
      auto tc = b.initTwistCovariance(9);
      if (e.index > 0) {
        const auto& o = victoria_->odometry[e.index - 1];
        twist.setVx(o.delta[0] / dt);
        twist.setVy(o.delta[1] / dt);
        twist.setOmega(o.delta[2] / dt);
        for (unsigned i = 0; i < 9; ++i) tc.set(i, o.covariance(i / 3, i % 3) / (dt * dt));
      }
      odom_pub_.publish(std::move(loan));
      ++odoms_;
      break;
    }
    case Kind::kLandmarks:
      publishScan(groups_[e.index], false, stamp);
      break;
    case Kind::kRobots:
      publishScan(groups_[e.index], true, stamp);
      break;
    case Kind::kControl: {
      auto loan = control_pub_.loan();
      auto b = loan.builder();
      setHeader(b.initHeader(), stamp, "base_link", control_pub_.nextSeq());
      b.setSteering(0);
      b.setWheelbase(0);
      if (mrclam_) {
        const auto& odo = mrclam_->odometry;
        b.setSpeed(odo[e.index].v);
        b.setTurnRate(odo[e.index].omega);
        b.setDtS(e.index + 1 < odo.size() ? odo[e.index + 1].time - odo[e.index].time : 0.0);
      } else {
        const double dt = nanosToSeconds(step_);
        const Eigen::Vector3d& d = victoria_->odometry[e.index].delta;
        b.setSpeed(arcLength(d[0], d[1], d[2]) / dt);
        b.setTurnRate(d[2] / dt);
        b.setDtS(dt);
      }
      control_pub_.publish(std::move(loan));
      ++controls_;
      break;
    }
  }
}

void LandmarkPlayerActor::publishScan(const Group& g, bool robots, Nanos stamp) {
  const auto& pub = robots ? robots_pub_ : landmarks_pub_;
  std::size_t count = 0;
  if (mrclam_) {
    for (std::size_t i = g.begin; i < g.end; ++i)
      count += mrclam_->measurements[i].is_robot == robots ? 1 : 0;
  } else {
    count = g.end - g.begin;
  }
  auto loan = pub.loan(count * 48 + 128);
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, mrclam_ ? "camera" : "laser", pub.nextSeq());
  b.setMountX(0);
  b.setMountY(0);
  b.setMountTheta(0);
  auto list = b.initObservations(static_cast<unsigned>(count));
  unsigned n = 0;
  if (mrclam_) {
    for (std::size_t i = g.begin; i < g.end; ++i) {
      const auto& m = mrclam_->measurements[i];
      if (m.is_robot != robots) continue;
      auto o = list[n++];
      o.setId(robots ? m.subject : m.landmark_index);
      o.setRange(m.range);
      o.setBearing(normalizeAngle(m.bearing));
      o.setRangeStd(options_.range_std);
      o.setBearingStd(options_.bearing_std);
    }
  } else {
    for (std::size_t i = g.begin; i < g.end; ++i) {
      const auto& m = victoria_->observations[victoria_order_[i]];
      auto o = list[n++];
      o.setId(static_cast<std::int32_t>(m.landmark_index));
      o.setRange(m.range);
      o.setBearing(m.bearing);
      o.setRangeStd(m.range_std);
      o.setBearingStd(m.bearing_std);
    }
  }
  pub.publish(std::move(loan));
  if (robots) {
    ++robot_scans_;
  } else {
    ++scans_;
    observations_ += static_cast<std::int64_t>(count);
  }
}

void LandmarkPlayerActor::summarize(Summary& out) const {
  out["events"] = static_cast<std::int64_t>(events_.size());
  out["controls_published"] = controls_;
  out["scans_published"] = scans_;
  out["observations_published"] = observations_;
  out["robot_scans_published"] = robot_scans_;
  out["odom_published"] = odoms_;
  out["ground_truth_published"] = ground_truth_;
  out["data_duration_s"] = events_.empty() ? 0.0 : nanosToSeconds(events_.back().time);
  out["lines_skipped"] =
      static_cast<std::int64_t>(mrclam_ ? mrclam_->report.skipped : victoria_->report.skipped);
}

TESSERA_REGISTER_ACTOR("landmark_player", LandmarkPlayerActor, LandmarkPlayerOptions,
                       "replays a landmark dataset (UTIAS MRCLAM or Victoria Park GTSAM text): "
                       "controls, range-bearing landmark scans, ground-truth landmark map");

}  // namespace tessera::players
