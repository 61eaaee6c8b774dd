#include <tessera/navigation/navigation_actor.hpp>

#include <tessera/actor_common/laser_scan.hpp>
#include <tessera/actor_common/map_message.hpp>
#include <tessera/actor_common/pose_source.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <ctime>
#include <iostream>
#include <limits>
#include <stdexcept>
#include <utility>

namespace tessera::navigation {

namespace {

constexpr const char* kName = "navigator";
constexpr std::uint64_t kReportedPerKind = 5;  // stderr lines per kind of bad input

double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

[[noreturn]] void fail(const std::string& key, const std::string& rule) {
  throw ConfigError(std::string(kName) + ": option '" + key + "' " + rule);
}

void checkPositive(const char* key, double value) {
  if (!(std::isfinite(value) && value > 0))
    fail(key, "must be finite and > 0, got " + std::to_string(value));
}

NavigationActorOptions checked(NavigationActorOptions o) {
  const auto nested = [](const char* key, auto&& validate) {
    try {
      validate();
    } catch (const std::invalid_argument& e) {
      fail(key, e.what());
    }
  };
  nested("navigator", [&] { o.navigator.validate(); });
  nested("static_layer", [&] { o.static_layer.validate(); });
  nested("inflation", [&] { o.inflation.validate(); });
  nested("obstacles", [&] { o.obstacles.validate(); });
  checkPositive("control_hz", o.control_hz);
  checkPositive("costmap_hz", o.costmap_hz);
  checkPositive("local_size", o.local_size);
  checkPositive("bounds_resolution", o.bounds_resolution);
  if (o.landmarks < 0 || o.landmarks > 16)
    fail("landmarks", "must be in [0, 16], got " + std::to_string(o.landmarks));
  checkPositive("pose_timeout_s", o.pose_timeout_s);
  checkPositive("status_period_s", o.status_period_s);
  if (!(std::isfinite(o.local_plan_hz) && o.local_plan_hz >= 0))
    fail("local_plan_hz",
         "must be finite and >= 0 (0: off), got " + std::to_string(o.local_plan_hz));
  if (o.local_plan_points < 2)
    fail("local_plan_points", "must be at least 2, got " + std::to_string(o.local_plan_points));
  if (!(std::isfinite(o.laser_height) && o.laser_height >= 0))
    fail("laser_height", "must be finite and >= 0");
  if (o.depth_stride < 1) fail("depth_stride", "must be at least 1");
  if (!o.bounds.empty() &&
      (o.bounds.size() != 4 ||
       !Eigen::Vector4d(o.bounds[0], o.bounds[1], o.bounds[2], o.bounds[3]).allFinite() ||
       !(o.bounds[2] > o.bounds[0] && o.bounds[3] > o.bounds[1]) ||
       (o.bounds[2] - o.bounds[0]) * (o.bounds[3] - o.bounds[1]) > 1e6))
    fail("bounds", "must be [x0, y0, x1, y1] with x0 < x1, y0 < y1, finite, at most 1 km²");
  if (!o.depth_camera.isFinite()) fail("depth_camera", "must be finite numbers");
  if (o.frame_id.empty()) fail("frame_id", "must not be empty");
  if (o.pose_queue < 1 || o.odom_queue < 1 || o.scan_queue < 1 || o.pose_history < 2)
    fail("pose_queue, odom_queue, scan_queue", "must be >= 1 (pose_history >= 2)");
  // The navigator's dynamic window runs once per control period.
  o.navigator.dwa.period = 1.0 / o.control_hz;
  return o;
}

/// The fixed costmap of `bounds`, all unknown.
Costmap boundsFrame(const NavigationActorOptions& o) {
  const auto& b = o.bounds;
  const double res = o.bounds_resolution;
  return Costmap(static_cast<int>(std::ceil((b[2] - b[0]) / res)),
                 static_cast<int>(std::ceil((b[3] - b[1]) / res)), res, Pose2(b[0], b[1], 0.0),
                 cost::kUnknown);
}

/// Cost -> OccupancyGrid value, as ROS costmap_2d publishes costmaps: free 0, 1-252 linearly to
/// 1-98, inscribed 99, lethal 100, unknown -1.
constexpr std::array<std::int8_t, 256> kCostToOccupancy = [] {
  std::array<std::int8_t, 256> t{};
  for (int c = 1; c <= cost::kMaxTraversable; ++c)
    t[static_cast<std::size_t>(c)] = static_cast<std::int8_t>(1 + ((c - 1) * 97 + 125) / 251);
  t[cost::kInscribed] = 99;
  t[cost::kLethal] = 100;
  t[cost::kUnknown] = -1;
  return t;
}();
static_assert(kCostToOccupancy[0] == 0 && kCostToOccupancy[1] == 1 && kCostToOccupancy[252] == 98);

msg::NavStatus::State messageState(NavState s) {
  switch (s) {
    case NavState::kIdle:
      return msg::NavStatus::State::IDLE;
    case NavState::kDriving:
    case NavState::kTurning:
      return msg::NavStatus::State::DRIVING;
    case NavState::kRecovering:
      return msg::NavStatus::State::RECOVERING;
    case NavState::kReached:
      return msg::NavStatus::State::REACHED;
    case NavState::kFailed:
      return msg::NavStatus::State::FAILED;
    case NavState::kRefused:
      return msg::NavStatus::State::REFUSED;
  }
  return msg::NavStatus::State::IDLE;
}

/// The window of `map` of side `size` [m] centred (to the cell) on p; cells outside `map` are
/// free (the static layer ends there; the planner never goes there).
Costmap window(const Costmap& map, const Eigen::Vector2d& p, double size) {
  const int n = std::max(3, static_cast<int>(std::ceil(size / map.resolution)));
  const Eigen::Vector2i c = map.cellOf(p);
  const int col0 = c.x() - n / 2, row0 = c.y() - n / 2;
  const Pose2 origin = map.origin * Pose2(col0 * map.resolution, row0 * map.resolution, 0);
  Costmap out(n, n, map.resolution, origin, cost::kFree);
  for (int r = 0; r < n; ++r)
    for (int q = 0; q < n; ++q)
      if (map.contains(col0 + q, row0 + r)) out.at(q, r) = map.at(col0 + q, row0 + r);
  return out;
}

}  // namespace

NavigationActor::NavigationActor(NavigationActorOptions options)
    : options_(checked(std::move(options))),
      navigator_(options_.navigator),
      odom_(static_cast<std::size_t>(options_.pose_history), 0.5) {
  parsePoseMessage(options_.pose_message, kName, "pose_message");
  camera_to_base_ = options_.depth_camera.opticalToBase();
  if (!options_.bounds.empty()) {  // drive on the sensors until a map comes
    static_ = boundsFrame(options_);
    obstacles_.emplace(static_, options_.obstacles);
  }
  if (options_.map_file.empty()) return;
  try {
    useMap(mapping::loadMap(options_.map_file));
  } catch (const std::exception& e) {
    throw ConfigError(std::string(kName) + ": map_file '" + options_.map_file + "': " + e.what());
  }
}

NavigationActor::~NavigationActor() = default;

void NavigationActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  subscribePoses(ctx, "pose",
                 MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.pose_queue)),
                 parsePoseMessage(options_.pose_message, kName, "pose_message"),
                 [this](Nanos stamp, const Pose2& pose) { onPose(stamp, pose); });
  ctx.subscribe<msg::Odometry>(
      "odom", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.odom_queue)),
      [this](const Message<msg::Odometry>& m) { onOdom(m); });
  if (options_.use_scan)
    ctx.subscribe<msg::LaserScan>(
        "scan", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.scan_queue)),
        [this](const Message<msg::LaserScan>& m) { onScan(m); });
  if (options_.use_depth)
    ctx.subscribe<msg::RgbdFrame>("rgbd", MailboxPolicy::keepLatest(1),
                                  [this](const Message<msg::RgbdFrame>& m) { onDepth(m); });
  ctx.subscribe<msg::NavGoal>("goal", MailboxPolicy::reliable(),
                              [this](const Message<msg::NavGoal>& m) { onGoal(m); });
  if (options_.map_file.empty())
    ctx.subscribe<msg::OccupancyGrid>("map", MailboxPolicy::keepLatest(1),
                                      [this](const Message<msg::OccupancyGrid>& m) { onMap(m); });
  cmd_pub_ = ctx.advertise<msg::Twist>("cmd_vel");
  status_pub_ = ctx.advertise<msg::NavStatus>("nav_status");
  path_pub_ = ctx.advertise<msg::Path>("path");
  if (options_.publish_costmap) costmap_pub_ = ctx.advertise<msg::OccupancyGrid>("costmap");
  if (options_.local_plan_hz > 0) local_plan_pub_ = ctx.advertise<msg::LocalPlan>("local_plan");
  const auto period = static_cast<Nanos>(std::llround(1e9 / options_.control_hz));
  ctx.addTimer(std::max<Nanos>(period, 1), [this] { tick(); });
}

void NavigationActor::bad(const std::string& kind, const std::string& what) {
  if (++bad_[kind] <= kReportedPerKind)
    std::cerr << "[" << ctx_->name() << "] " << what << "; skipped"
              << (bad_[kind] == kReportedPerKind ? " (further ones counted only)" : "") << "\n";
}

void NavigationActor::useMap(const grid::OccupancyMap& map) {
  Costmap costs = fromOccupancy(map, options_.static_layer);  // throws std::invalid_argument
  if (!options_.bounds.empty()) {
    Costmap frame = boundsFrame(options_);
    paste(costs, frame);
    costs = std::move(frame);
  }
  const bool same = !static_.empty() && sameGeometry(costs, static_);
  static_ = std::move(costs);
  if (!same) obstacles_.emplace(static_, options_.obstacles);
  buildLandmarks();
  obstacles_dirty_ = true;
  ++maps_;
}

void NavigationActor::buildLandmarks() {
  if (options_.landmarks == 0) return;
  // The reference must cost no more than any planning costmap to come: the obstacle layer adds
  // lethal cells and turns unknown cells it sees into free ones, so unknown counts free here.
  Costmap reference = static_;
  std::replace(reference.cells.begin(), reference.cells.end(), cost::kUnknown, cost::kFree);
  inflate(reference, options_.inflation);
  // A map server that publishes the same map again costs nothing: the bounds are kept.
  if (navigator_.landmarks() && sameGeometry(reference, landmark_reference_) &&
      reference.cells == landmark_reference_.cells)
    return;
  navigator_.setLandmarks(nullptr);
  const double t0 = threadCpuMs();
  try {
    navigator_.setLandmarks(std::make_shared<const LandmarkBounds>(
        reference, options_.navigator.planner, options_.landmarks));
  } catch (const std::exception& e) {  // a map without a passable cell: plan without them
    std::cerr << "[" << (ctx_ ? ctx_->name() : std::string(kName))
              << "] no landmark bounds: " << e.what() << "\n";
    return;
  }
  landmarks_ms_ = threadCpuMs() - t0;
  ++landmark_builds_;
  landmark_reference_ = std::move(reference);
}

void NavigationActor::onMap(const Message<msg::OccupancyGrid>& m) {
  try {
    useMap(toOccupancyMap(*m));
  } catch (const std::invalid_argument& e) {
    bad("map_invalid", std::string("map message: ") + e.what());
  }
}

void NavigationActor::onPose(Nanos stamp, const Pose2& pose) {
  if (!pose.isFinite()) return bad("pose_nan", "pose at " + std::to_string(stamp) + " ns");
  if (pose_ && stamp < pose_->first) return;  // an older pose than the one held
  pose_.emplace(stamp, pose);
  pose_received_ = ctx_->now();
}

void NavigationActor::onOdom(const Message<msg::Odometry>& m) {
  const Nanos stamp = m->getHeader().getStampNs();
  const Pose2 pose = toPose2(m->getPose());
  if (!odom_.add(stamp, pose)) return bad("odom_nan", "odometry at " + std::to_string(stamp));
  if (!odom_latest_ || stamp >= odom_latest_->first) odom_latest_.emplace(stamp, pose);
  const double v = m->getTwist().getVx(), w = m->getTwist().getOmega();
  if (std::isfinite(v) && std::isfinite(w)) velocity_ = {v, w};
}

std::optional<Pose2> NavigationActor::mapPoseAt(Nanos stamp) const {
  if (!pose_) return std::nullopt;
  Pose2 odom_then, odom_at;
  // Both odometry poses known: move the localised pose by the odometry between the stamps.
  const auto known = [&](Nanos t, Pose2& out) {
    if (odom_latest_ && t >= odom_latest_->first) {
      out = odom_latest_->second;  // newer than all odometry: hold the newest
      return true;
    }
    const auto r = odom_.at(t, out);
    return r == PoseHistory::Lookup::kExact || r == PoseHistory::Lookup::kInterpolated;
  };
  if (known(pose_->first, odom_then) && known(stamp, odom_at))
    return pose_->second * (odom_then.inverse() * odom_at);
  return pose_->second;
}

void NavigationActor::onScan(const Message<msg::LaserScan>& m) {
  if (!obstacles_) return;
  const double cpu0 = threadCpuMs();
  const Nanos stamp = m->getHeader().getStampNs();
  const auto base = mapPoseAt(stamp);
  if (!base) return;
  const auto ranges = view<float>(m->getRanges());
  const double a0 = m->getAngleMin(), da = m->getAngleIncrement();
  const double rmin = m->getRangeMin(), rmax = m->getRangeMax();
  const Pose2 mount = laserMountOf(*m);
  if (!(std::isfinite(a0) && std::isfinite(da) && std::isfinite(rmin) && std::isfinite(rmax) &&
        rmax > 0 && mount.isFinite()) ||
      ranges.empty())
    return bad("scan_invalid", "scan at " + std::to_string(stamp) +
                                   " ns: non-finite angles, range limits or mount, or no beams");
  const Pose2 sensor = *base * mount;
  const double clear = options_.obstacles.clear_range;
  std::vector<Eigen::Vector2d>& ends = scan_ends_;  // members: no allocation per scan
  std::vector<std::uint8_t>& no_return = scan_no_return_;
  ends.clear();
  no_return.clear();
  for (std::size_t i = 0; i < ranges.size(); ++i) {
    const double r = ranges[i];
    if (std::isnan(r) || r < rmin) continue;
    const bool none = !(r < rmax);
    const double a = sensor.theta + a0 + da * static_cast<double>(i);
    const double d = none ? std::min(clear, rmax) : r;
    ends.emplace_back(sensor.x + d * std::cos(a), sensor.y + d * std::sin(a));
    no_return.push_back(none ? 1 : 0);
  }
  obstacles_->addScan(Eigen::Vector3d(sensor.x, sensor.y, options_.laser_height), ends, no_return);
  obstacles_dirty_ = true;
  ++scans_;
  sensor_cpu_ms_ += threadCpuMs() - cpu0;
}

void NavigationActor::onDepth(const Message<msg::RgbdFrame>& m) {
  if (!obstacles_) return;
  const double cpu0 = threadCpuMs();
  const Nanos stamp = m->getHeader().getStampNs();
  const auto base = mapPoseAt(stamp);
  if (!base) return;
  const auto depth = m->getDepth();
  const auto k = m->getIntrinsics();
  const std::string enc = depth.getEncoding();
  const std::uint32_t w = depth.getWidth(), h = depth.getHeight(), step = depth.getStep();
  const auto data = depth.getData();
  const bool u16 = enc == "16UC1", f32 = enc == "32FC1";
  const std::size_t bpp = u16 ? 2 : 4;
  const double scale = u16 ? m->getDepthScale() : 1.0;
  const std::string what = "depth at " + std::to_string(stamp) + " ns: ";
  if (!u16 && !f32) return bad("depth_encoding", what + "encoding '" + enc + "'");
  if (w == 0 || h == 0 || step < w * bpp || data.size() < static_cast<std::size_t>(step) * h)
    return bad("depth_size", what + std::to_string(w) + "x" + std::to_string(h) + ", step " +
                                 std::to_string(step) + ", " + std::to_string(data.size()) +
                                 " bytes");
  const double fx = k.getFx(), fy = k.getFy(), cx = k.getCx(), cy = k.getCy();
  if (!(std::isfinite(fx) && std::isfinite(fy) && std::isfinite(cx) && std::isfinite(cy) &&
        fx > 0 && fy > 0 && std::isfinite(scale) && scale > 0))
    return bad("depth_intrinsics", what + "bad intrinsics or depth scale");

  Eigen::Isometry3d world_base = Eigen::Isometry3d::Identity();
  world_base.translate(Eigen::Vector3d(base->x, base->y, 0));
  world_base.rotate(Eigen::AngleAxisd(base->theta, Eigen::Vector3d::UnitZ()));
  const Eigen::Isometry3d camera = world_base * camera_to_base_;
  const double max_range = std::max(options_.obstacles.clear_range, options_.obstacles.mark_range);
  std::vector<Eigen::Vector3d>& points = depth_points_;  // a member: no allocation per frame
  points.clear();
  const auto stride = static_cast<std::uint32_t>(options_.depth_stride);
  for (std::uint32_t v = stride / 2; v < h; v += stride) {
    const auto* row = data.begin() + static_cast<std::size_t>(v) * step;
    for (std::uint32_t u = stride / 2; u < w; u += stride) {
      double z = 0;
      if (u16) {
        std::uint16_t raw = 0;
        std::memcpy(&raw, row + static_cast<std::size_t>(u) * 2, 2);
        z = raw / scale;
      } else {
        float f = 0;
        std::memcpy(&f, row + static_cast<std::size_t>(u) * 4, 4);
        z = f;
      }
      if (!(std::isfinite(z) && z > 0)) continue;
      Eigen::Vector3d p((u - cx) * z / fx, (v - cy) * z / fy, z);
      if (p.norm() > max_range) p *= max_range / p.norm();  // beyond: clears only up to there
      points.push_back(camera * p);
    }
  }
  obstacles_->addPoints(camera.translation(), points);
  obstacles_dirty_ = true;
  ++depth_frames_;
  sensor_cpu_ms_ += threadCpuMs() - cpu0;
}

void NavigationActor::onGoal(const Message<msg::NavGoal>& m) {
  PendingGoal g;
  g.id = m->getId();
  g.pose = toPose2(m->getPose());
  g.tolerance_xy = m->getToleranceXy();
  g.tolerance_yaw = m->getToleranceYaw();
  const std::string frame = m->getHeader().getFrameId();
  ++goals_;
  goal_id_ = g.id;
  if (!frame.empty() && frame != options_.frame_id) {
    last_state_ = NavState::kRefused;
    last_reason_ = "goal in frame '" + frame + "', expected '" + options_.frame_id + "'";
    ++refused_;
    navigator_.cancel();
    pending_.reset();
    return publishStatus(true);
  }
  // A NaN yaw tolerance means "heading does not matter" (NavGoal); the navigator reads +inf so.
  if (std::isnan(g.tolerance_yaw)) g.tolerance_yaw = std::numeric_limits<double>::infinity();
  pending_ = g;
}

void NavigationActor::rebuildCostmap() {
  const double cpu0 = threadCpuMs();
  combined_ = static_;
  obstacles_->applyTo(combined_);
  planning_ = combined_;
  inflate(planning_, options_.inflation);
  obstacles_dirty_ = false;
  last_costmap_ = ctx_->now();
  ++costmap_builds_;
  if (options_.publish_costmap) publishCostmap();
  costmap_cpu_ms_ += threadCpuMs() - cpu0;
}

void NavigationActor::publishCostmap() {
  // A static map while idle is rebuilt unchanged at costmap_hz: send it once.
  if (!published_costmap_.empty() && sameGeometry(planning_, published_costmap_) &&
      planning_.cells == published_costmap_.cells)
    return;
  const std::size_t cells = planning_.cells.size();
  auto loan = costmap_pub_.loanWithBlob(cells, 512);
  setHeader(loan->initHeader(), ctx_->now(), options_.frame_id, costmap_pub_.nextSeq());
  loan->setResolution(static_cast<float>(planning_.resolution));
  loan->setWidth(static_cast<std::uint32_t>(planning_.width));
  loan->setHeight(static_cast<std::uint32_t>(planning_.height));
  writePose(loan->initOrigin(), planning_.origin);
  auto* out = reinterpret_cast<std::int8_t*>(loan.blob().data());
  for (std::size_t i = 0; i < cells; ++i) out[i] = kCostToOccupancy[planning_.cells[i]];
  loan->adoptCells(loan.blobData());
  costmap_pub_.publish(std::move(loan));
  published_costmap_ = planning_;
  ++costmaps_published_;
}

void NavigationActor::tick() {
  const Nanos now = ctx_->now();
  if (first_tick_ < 0) first_tick_ = now;
  last_tick_ = now;
  if (static_.empty()) return publishCommand({});
  const double cpu0 = threadCpuMs();
  const auto costmap_period = static_cast<Nanos>(1e9 / options_.costmap_hz);
  if (planning_.empty() || (obstacles_dirty_ && now - last_costmap_ >= costmap_period))
    rebuildCostmap();

  if (pending_) {
    const PendingGoal g = *pending_;
    pending_.reset();
    const std::string why = navigator_.setGoal(g.pose, planning_, g.tolerance_xy, g.tolerance_yaw);
    if (!why.empty()) {
      ++refused_;
      last_state_ = NavState::kRefused;
      last_reason_ = why;
      publishStatus(true);
    } else {
      outcome_counted_ = false;
    }
  }

  const auto pose = mapPoseAt(now);
  const bool stale = !pose || nanosToSeconds(now - pose_received_) > options_.pose_timeout_s;
  if (stale != stale_ && stale && navigator_.goal() && !isFinal(navigator_.state())) ++stale_stops_;
  stale_ = stale;
  if (stale) {
    publishCommand({});
    if (navigator_.goal() && !isFinal(navigator_.state())) {
      last_reason_ = "stale localisation: no pose for " +
                     std::to_string(pose ? nanosToSeconds(now - pose_received_) : 0.0) + " s";
      publishStatus(false);
    }
    return;
  }

  const DistanceField field(window(combined_, pose->translation(), options_.local_size));
  // The dynamic window rolls out every arc only in the periods that publish a local plan.
  const Nanos plan_period =
      options_.local_plan_hz > 0 ? std::llround(1e9 / options_.local_plan_hz) : 0;
  const bool plan_due =
      plan_period > 0 && (!last_local_plan_ || now - *last_local_plan_ >= plan_period);
  navigator_.setKeepArcs(plan_due);
  const NavCommand cmd = navigator_.step(nanosToSeconds(now), *pose, velocity_, planning_, field);
  if (plan_due)
    if (const DynamicWindowResult* w = navigator_.lastWindow()) publishLocalPlan(now, *w);
  // The goal ended: one plan without arcs tells viewers to remove the last one.
  if (local_plan_shown_ && (cmd.state == NavState::kIdle || isFinal(cmd.state)))
    publishLocalPlan(now, DynamicWindowResult{});
  if (cmd.clear_obstacles && obstacles_) {
    obstacles_->clear();
    obstacles_dirty_ = true;
  }
  if (cmd.replanned) publishPath();
  publishCommand(cmd.velocity);
  distance_remaining_ = cmd.distance_remaining;

  // A goal refused here (another frame) leaves the navigator idle: the refusal stays the status.
  if (cmd.state == NavState::kIdle && isFinal(last_state_)) {
    ++ticks_;
    control_cpu_ms_ += threadCpuMs() - cpu0;
    return;
  }
  const bool changed = cmd.state != last_state_ || cmd.reason != last_reason_;
  if (isFinal(cmd.state) && !outcome_counted_) {
    if (cmd.state == NavState::kReached) ++reached_;
    if (cmd.state == NavState::kFailed) ++failed_;
    if (cmd.state == NavState::kRefused) ++refused_;
    outcome_counted_ = true;
  }
  last_state_ = cmd.state;
  last_reason_ = cmd.reason;
  publishStatus(changed);
  ++ticks_;
  const double ms = threadCpuMs() - cpu0;
  control_cpu_ms_ += ms;
  control_cpu_max_ms_ = std::max(control_cpu_max_ms_, ms);
}

void NavigationActor::publishCommand(const Velocity& v) {
  Velocity out = v;
  if (!(std::isfinite(out.v) && std::isfinite(out.w))) {
    ++nonfinite_commands_;
    out = {};
  }
  auto loan = cmd_pub_.loan();
  setHeader(loan->initHeader(), ctx_->now(), "base_link", cmd_pub_.nextSeq());
  auto t = loan->initTwist();
  t.setVx(out.v);
  t.setVy(0);
  t.setOmega(out.w);
  cmd_pub_.publish(std::move(loan));
}

void NavigationActor::publishStatus(bool force) {
  const Nanos now = ctx_->now();
  const bool active = navigator_.goal() && !isFinal(last_state_);
  if (!force && !(active && nanosToSeconds(now - last_status_) >= options_.status_period_s)) return;
  last_status_ = now;
  auto loan = status_pub_.loan();
  setHeader(loan->initHeader(), now, options_.frame_id, status_pub_.nextSeq());
  loan->setGoalId(goal_id_);
  loan->setState(messageState(last_state_));
  loan->setReason(last_reason_);
  loan->setDistanceRemaining(navigator_.path().empty() ? std::numeric_limits<double>::quiet_NaN()
                                                       : distance_remaining_);
  status_pub_.publish(std::move(loan));
}

void NavigationActor::publishPath() {
  const auto& path = navigator_.path();
  auto loan = path_pub_.loan(path.size() * 64 + 256);
  const Nanos now = ctx_->now();
  setHeader(loan->initHeader(), now, options_.frame_id, path_pub_.nextSeq());
  auto poses = loan->initPoses(static_cast<unsigned>(path.size()));
  for (std::size_t i = 0; i < path.size(); ++i) {
    auto p = poses[static_cast<unsigned>(i)];
    setHeader(p.initHeader(), now, options_.frame_id, i);
    const Eigen::Vector2d d = i + 1 < path.size() ? Eigen::Vector2d(path[i + 1] - path[i])
                              : i > 0             ? Eigen::Vector2d(path[i] - path[i - 1])
                                                  : Eigen::Vector2d(1, 0);
    writePose(p.initPose(), Pose2(path[i].x(), path[i].y(), std::atan2(d.y(), d.x())));
  }
  path_pub_.publish(std::move(loan));
  ++paths_published_;
}

void NavigationActor::publishLocalPlan(Nanos stamp, const DynamicWindowResult& window) {
  // Each arc keeps `points` of its poses, evenly spaced by index, the first and the last among
  // them: with the default window (231 arcs of 31 poses) and 16 points, ~40 KB a message.
  const auto n = static_cast<unsigned>(window.arcs.size());
  const std::size_t poses = window.arcs.empty() ? 0 : window.arcs.front().poses.size();
  const std::size_t points = std::min(poses, static_cast<std::size_t>(options_.local_plan_points));
  auto loan = local_plan_pub_.loan(256 + n * (40 + points * 8));
  setHeader(loan->initHeader(), stamp, options_.frame_id, local_plan_pub_.nextSeq());
  loan->setGoalId(goal_id_);
  auto command = loan->initCommand();
  command.setVx(window.command.v);
  command.setVy(0);
  command.setOmega(window.command.w);
  loan->setChosen(window.ok ? window.chosen : -1);
  auto arcs = loan->initArcs(n);
  for (unsigned i = 0; i < n; ++i) {
    const DynamicWindowArc& a = window.arcs[i];
    auto out = arcs[i];
    out.setV(static_cast<float>(a.velocity.v));
    out.setW(static_cast<float>(a.velocity.w));
    out.setAdmissible(a.admissible);
    out.setScore(static_cast<float>(a.score));
    out.setClearance(static_cast<float>(a.clearance));
    const std::size_t m = std::min(points, a.poses.size());
    auto xy = out.initXy(static_cast<unsigned>(2 * m));
    for (std::size_t k = 0; k < m; ++k) {
      const std::size_t at = m > 1 ? (k * (a.poses.size() - 1) + (m - 1) / 2) / (m - 1) : 0;
      xy.set(static_cast<unsigned>(2 * k), static_cast<float>(a.poses[at].x));
      xy.set(static_cast<unsigned>(2 * k + 1), static_cast<float>(a.poses[at].y));
    }
  }
  local_plan_pub_.publish(std::move(loan));
  local_plan_shown_ = n > 0;
  last_local_plan_ = stamp;
  ++local_plans_published_;
}

void NavigationActor::summarize(Summary& out) const {
  const NavigatorStats& s = navigator_.stats();
  out["goals"] = static_cast<std::int64_t>(goals_);
  out["reached"] = static_cast<std::int64_t>(reached_);
  out["failed"] = static_cast<std::int64_t>(failed_);
  out["refused"] = static_cast<std::int64_t>(refused_);
  out["plans"] = static_cast<std::int64_t>(s.plans);
  out["plan_failures"] = s.plan_failures;
  out["plan_ms_mean"] = s.plans > 0 ? s.plan_ms_total / s.plans : 0.0;
  out["plan_ms_max"] = s.plan_ms_max;
  out["landmark_plans"] = static_cast<std::int64_t>(s.landmark_plans);
  out["landmarks_ms"] = landmarks_ms_;  // building the last map's landmark bounds (CPU)
  out["landmark_builds"] = static_cast<std::int64_t>(landmark_builds_);
  out["recoveries"] = s.recoveries;
  out["dwa_failures"] = s.dwa_failures;
  out["stale_stops"] = static_cast<std::int64_t>(stale_stops_);
  out["nonfinite_commands"] = static_cast<std::int64_t>(nonfinite_commands_);
  out["control_ticks"] = static_cast<std::int64_t>(ticks_);
  out["control_ms_mean"] = ticks_ > 0 ? control_cpu_ms_ / static_cast<double>(ticks_) : 0.0;
  out["control_ms_max"] = control_cpu_max_ms_;
  out["costmap_builds"] = static_cast<std::int64_t>(costmap_builds_);
  out["costmap_ms_mean"] =
      costmap_builds_ > 0 ? costmap_cpu_ms_ / static_cast<double>(costmap_builds_) : 0.0;
  out["scans"] = static_cast<std::int64_t>(scans_);
  out["depth_frames"] = static_cast<std::int64_t>(depth_frames_);
  out["maps"] = static_cast<std::int64_t>(maps_);
  out["paths_published"] = static_cast<std::int64_t>(paths_published_);
  out["costmaps_published"] = static_cast<std::int64_t>(costmaps_published_);
  out["local_plans_published"] = static_cast<std::int64_t>(local_plans_published_);
  // Shares of one core over the run's clock (simulated time in the simulator).
  const double span_ms = first_tick_ >= 0 ? nanosToSeconds(last_tick_ - first_tick_) * 1e3 : 0.0;
  if (span_ms > 0) {
    out["control_core_fraction"] = (control_cpu_ms_ - costmap_cpu_ms_) / span_ms;
    out["costmap_core_fraction"] = costmap_cpu_ms_ / span_ms;
    out["sensor_core_fraction"] = sensor_cpu_ms_ / span_ms;
  }
  for (const auto& [kind, n] : bad_) out["bad_" + kind] = static_cast<std::int64_t>(n);
}

TESSERA_REGISTER_ACTOR("navigator", NavigationActor, NavigationActorOptions,
                       "drives to goals on a known map: costmaps from laser and depth, global "
                       "planner, dynamic window, recoveries; publishes cmd_vel");

}  // namespace tessera::navigation
