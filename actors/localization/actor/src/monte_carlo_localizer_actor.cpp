// monte_carlo_localizer actor: scans + odometry -> MonteCarloLocalizer -> localized_pose and
// map_to_odom.
#include <tessera/localization/monte_carlo_localizer_actor.hpp>

#include <tessera/actor_common/laser_scan.hpp>
#include <tessera/actor_common/map_message.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <numeric>
#include <stdexcept>
#include <utility>

namespace tessera::localization {
namespace {

const MonteCarloLocalizerActorOptions& checked(const MonteCarloLocalizerActorOptions& o) {
  const auto fail = [](const std::string& what) {
    throw ConfigError("monte_carlo_localizer: " + what);
  };
  try {
    o.mcl.validate();
    o.mcl.field.validate();
  } catch (const std::invalid_argument& e) {
    fail(std::string("mcl: ") + e.what());
  }
  if (!(std::isfinite(o.range_max) && o.range_max >= 0))
    fail("range_max must be >= 0 (got " + std::to_string(o.range_max) + ")");
  const InitialPoseOptions& i = o.initial;
  if (!(std::isfinite(i.x) && std::isfinite(i.y) && std::isfinite(i.theta)))
    fail("initial.x, initial.y and initial.theta must be finite");
  if (!(std::isfinite(i.sigma_xy) && i.sigma_xy >= 0))
    fail("initial.sigma_xy must be >= 0 (got " + std::to_string(i.sigma_xy) + ")");
  if (!(std::isfinite(i.sigma_theta) && i.sigma_theta >= 0))
    fail("initial.sigma_theta must be >= 0 (got " + std::to_string(i.sigma_theta) + ")");
  if (!(std::isfinite(o.max_pose_gap_s) && o.max_pose_gap_s > 0))
    fail("max_pose_gap_s must be > 0 (got " + std::to_string(o.max_pose_gap_s) + ")");
  if (o.scan_queue < 1 || o.odom_queue < 1 || o.scan_buffer < 1 || o.pose_history < 2)
    fail("scan_queue, odom_queue, scan_buffer must be >= 1 and pose_history >= 2");
  if (o.frame_id.empty()) fail("frame_id must not be empty");
  return o;
}

/// The covariance of the options' start: sigma² on the diagonal (a small floor keeps the
/// Cholesky factor of a zero spread defined).
Eigen::Matrix3d startCovariance(const InitialPoseOptions& i) {
  const double xy = std::max(i.sigma_xy * i.sigma_xy, 1e-12);
  const double th = std::max(i.sigma_theta * i.sigma_theta, 1e-12);
  return Eigen::Vector3d(xy, xy, th).asDiagonal();
}

}  // namespace

MonteCarloLocalizerActor::MonteCarloLocalizerActor(MonteCarloLocalizerActorOptions options)
    : options_(checked(options)),
      odom_(static_cast<std::size_t>(options_.pose_history), options_.max_pose_gap_s) {
  if (options_.map_file.empty()) return;
  try {
    grid::OccupancyMap map = mapping::loadMap(options_.map_file);
    // The likelihood field's own checks (sizes, thresholds), before the run starts.
    LikelihoodField probe(map, options_.range_max > 0 ? options_.range_max : 1.0,
                          options_.mcl.field);
    map_ = std::move(map);
  } catch (const std::exception& e) {
    throw ConfigError("monte_carlo_localizer: map_file '" + options_.map_file + "': " + e.what());
  }
  map_source_ = options_.map_file;
  ++maps_;
}

MonteCarloLocalizerActor::~MonteCarloLocalizerActor() = default;

void MonteCarloLocalizerActor::configure(ActorContext& ctx) {
  ctx.subscribe<msg::LaserScan>(
      "scan", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.scan_queue)),
      [this](const Message<msg::LaserScan>& m) { onScan(m); });
  ctx.subscribe<msg::Odometry>(
      "odom", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.odom_queue)),
      [this](const Message<msg::Odometry>& m) { onOdom(m); });
  if (options_.initial_pose_topic)
    ctx.subscribe<msg::PoseStamped>(
        "initial_pose", MailboxPolicy::reliable(),
        [this](const Message<msg::PoseStamped>& m) { onInitialPose(m); });
  if (options_.map_file.empty())
    ctx.subscribe<msg::OccupancyGrid>("map", MailboxPolicy::keepLatest(1),
                                      [this](const Message<msg::OccupancyGrid>& m) { onMap(m); });
  pose_pub_ = ctx.advertise<msg::PoseStamped>("localized_pose");
  map_to_odom_pub_ = ctx.advertise<msg::PoseStamped>("map_to_odom");
}

void MonteCarloLocalizerActor::bad(const std::string& kind, const std::string& why) {
  // The first few of a kind are logged; all are counted.
  if (++bad_[kind] <= 3) std::cerr << "[monte_carlo_localizer] " << why << "; skipped\n";
}

void MonteCarloLocalizerActor::onOdom(const Message<msg::Odometry>& m) {
  if (!odom_.add(m->getHeader().getStampNs(), toPose2(m->getPose())))
    return bad("odom_invalid", "odometry pose not finite");
  while (!waiting_.empty() && tryScan(waiting_.front())) waiting_.pop_front();
}

void MonteCarloLocalizerActor::onScan(const Message<msg::LaserScan>& scan) {
  ++scans_;
  // Scans queued behind this one keep their order: only try it now if none is waiting.
  if (waiting_.empty() && tryScan(scan)) return;
  if (waiting_.size() >= static_cast<std::size_t>(options_.scan_buffer)) {
    waiting_.pop_front();
    bad("scan_no_pose", "scan waiting for odometry dropped (buffer full)");
  }
  waiting_.push_back(scan);
}

void MonteCarloLocalizerActor::onInitialPose(const Message<msg::PoseStamped>& m) {
  const Pose2 pose = toPose2(m->getPose());
  if (!pose.isFinite()) return bad("initial_pose_invalid", "initial_pose not finite");
  Eigen::Matrix3d cov;
  if (!readCovariance(m->getPose(), cov) || !cov.allFinite() || (cov.diagonal().array() < 0).any())
    cov = startCovariance(options_.initial);
  ++initial_poses_;
  pending_start_.emplace(pose, cov);
  start_pending_ = true;
  if (mcl_) startFilter();
}

void MonteCarloLocalizerActor::onMap(const Message<msg::OccupancyGrid>& m) {
  try {
    useMap(toOccupancyMap(*m));
  } catch (const std::invalid_argument& e) {
    return bad("map_invalid", std::string("map message: ") + e.what());
  }
  map_source_ = "topic";
  ++maps_;
}

void MonteCarloLocalizerActor::useMap(grid::OccupancyMap map) {
  if (mcl_)
    mcl_->setMap(map);  // throws std::invalid_argument, the filter unchanged
  else
    map_ = std::move(map);
}

void MonteCarloLocalizerActor::startFilter() {
  if (pending_start_)
    mcl_->initialise(pending_start_->first, pending_start_->second);
  else if (options_.global)
    mcl_->initialiseGlobal();
  else
    mcl_->initialise({options_.initial.x, options_.initial.y, options_.initial.theta},
                     startCovariance(options_.initial));
  start_pending_ = false;
}

bool MonteCarloLocalizerActor::tryScan(const Message<msg::LaserScan>& scan) {
  const Nanos stamp = scan->getHeader().getStampNs();
  Pose2 odom;
  switch (odom_.at(stamp, odom)) {
    case PoseHistory::Lookup::kWait:
      return false;
    case PoseHistory::Lookup::kTooOld:
    case PoseHistory::Lookup::kGap:
      bad("scan_no_pose", "no odometry pose at the scan's stamp");
      return true;
    case PoseHistory::Lookup::kExact:
    case PoseHistory::Lookup::kInterpolated:
      break;
  }
  const double angle_min = scan->getAngleMin(), increment = scan->getAngleIncrement();
  const double range_min = scan->getRangeMin(), scan_max = scan->getRangeMax();
  const Pose2 mount = laserMountOf(*scan);
  if (!(std::isfinite(angle_min) && std::isfinite(increment) && increment != 0 &&
        std::isfinite(scan_max) && scan_max > 0 && std::isfinite(range_min) && mount.isFinite()))
    return bad("scan_fields", "scan with a non-finite or zero angle step, or bad range or mount"),
           true;
  const double limit = options_.range_max > 0 ? std::min(options_.range_max, scan_max) : scan_max;
  const auto ranges = view<float>(scan->getRanges());
  points_.clear();
  for (std::size_t i = 0; i < ranges.size(); ++i) {
    const double r = ranges[i];
    if (!(std::isfinite(r) && r >= range_min && r < limit)) continue;
    const double a = angle_min + static_cast<double>(i) * increment;
    points_.push_back(mount * Eigen::Vector2d(r * std::cos(a), r * std::sin(a)));
  }
  beams_dropped_ += ranges.size() - points_.size();
  if (points_.empty()) return bad("scan_empty", "scan without a usable beam"), true;

  if (!mcl_) {
    if (!map_) return bad("scan_no_map", "scan before any map"), true;
    try {
      mcl_ = std::make_unique<MonteCarloLocalizer>(
          *map_, options_.range_max > 0 ? options_.range_max : scan_max, options_.mcl);
    } catch (const std::invalid_argument& e) {
      map_.reset();  // refused: wait for another map
      return bad("map_invalid", std::string("map: ") + e.what()), true;
    }
    map_.reset();
  }
  if (start_pending_) {
    try {
      startFilter();
    } catch (const std::invalid_argument& e) {  // e.g. a map without free cells
      return bad("start_failed", e.what()), true;
    }
  }
  ++scans_used_;
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  const bool updated = mcl_->update(odom, points_);
  if (updated) {
    update_ms_.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    ++updates_;
    beams_used_ += points_.size();
    const std::size_t n = mcl_->particles().size();
    particles_sum_ += n;
    particles_min_ = updates_ == 1 ? n : std::min(particles_min_, n);
    particles_max_ = std::max(particles_max_, n);
    const double share = mcl_->randomShare();
    random_share_sum_ += share;
    random_share_max_ = std::max(random_share_max_, share);
    inlier_fraction_sum_ += mcl_->inlierFraction();
  }
  publish(stamp, updated, odom);
  return true;
}

void MonteCarloLocalizerActor::publish(Nanos stamp, bool updated, const Pose2& odom) {
  if (!updated && !options_.pose_every_scan) return;
  const PoseEstimate e = mcl_->estimate();
  const Pose2 pose = updated ? e.pose : e.pose * between(e.odom, odom);
  if (!pose.isFinite() || !e.covariance.allFinite())
    return bad("estimate_invalid", "estimate not finite, not published");
  auto loan = pose_pub_.loan();
  setHeader(loan->initHeader(), stamp, options_.frame_id, pose_pub_.nextSeq());
  writePose(loan->initPose(), pose, &e.covariance);
  pose_pub_.publish(std::move(loan));
  ++poses_published_;
  if (!updated) return;
  auto correction = map_to_odom_pub_.loan();
  setHeader(correction->initHeader(), stamp, options_.frame_id, map_to_odom_pub_.nextSeq());
  writePose(correction->initPose(), e.pose * e.odom.inverse());
  map_to_odom_pub_.publish(std::move(correction));
}

void MonteCarloLocalizerActor::stop() {
  // Upstream has stopped: no odometry will come for scans still waiting.
  for (std::size_t i = 0; i < waiting_.size(); ++i) ++bad_["scan_no_pose"];
  waiting_.clear();
}

void MonteCarloLocalizerActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["scans_received"] = i64(scans_);
  out["scans_used"] = i64(scans_used_);
  out["updates"] = i64(updates_);
  out["poses_published"] = i64(poses_published_);
  out["initial_poses"] = i64(initial_poses_);
  out["maps_received"] = i64(maps_);
  if (!map_source_.empty()) out["map_source"] = map_source_;
  const grid::OccupancyMap* map = mcl_ ? &mcl_->field().map() : (map_ ? &*map_ : nullptr);
  if (map) {
    out["map_width"] = static_cast<std::int64_t>(map->width);
    out["map_height"] = static_cast<std::int64_t>(map->height);
    out["map_resolution"] = map->resolution;
  }
  std::uint64_t bad_total = 0;
  for (const auto& [kind, n] : bad_) {
    out["bad_" + kind] = i64(n);
    bad_total += n;
  }
  out["bad_input"] = i64(bad_total);
  out["beams_dropped"] = i64(beams_dropped_);
  if (updates_ == 0) return;
  const double n = static_cast<double>(updates_);
  // Beams left after the range and NaN checks; the filter weighs up to mcl.max_beams of them.
  out["usable_beams_mean"] = static_cast<double>(beams_used_) / n;
  out["particles_mean"] = static_cast<double>(particles_sum_) / n;
  out["particles_min"] = static_cast<std::int64_t>(particles_min_);
  out["particles_max"] = static_cast<std::int64_t>(particles_max_);
  out["random_share_mean"] = random_share_sum_ / n;
  out["random_share_max"] = random_share_max_;
  // Share of the best particle's beams near an obstacle, and the global re-spreads it caused.
  out["inlier_fraction_mean"] = inlier_fraction_sum_ / n;
  out["relocalisations"] = static_cast<std::int64_t>(mcl_->relocalisations());
  // Scan-matched refinements of the estimate (mcl.refine_step > 0), and those refused as too far.
  out["refinements"] = static_cast<std::int64_t>(mcl_->refinements());
  out["refinements_refused"] = static_cast<std::int64_t>(mcl_->refinementsRefused());
  // Wall time of the filter step (motion, TBB-parallel weighting, resampling); with one executor
  // thread (tessera run --threads 1) it is the CPU time per update.
  std::vector<double> ms = update_ms_;
  std::sort(ms.begin(), ms.end());
  out["update_ms_mean"] = std::accumulate(ms.begin(), ms.end(), 0.0) / n;
  out["update_ms_p95"] = ms[std::min(ms.size() - 1, static_cast<std::size_t>(0.95 * ms.size()))];
  out["update_ms_max"] = ms.back();
  const PoseEstimate e = mcl_->estimate();
  out["clusters"] = static_cast<std::int64_t>(e.clusters);
  out["position_sigma_m"] = std::sqrt(std::max(0.0, e.covariance(0, 0) + e.covariance(1, 1)));
}

TESSERA_REGISTER_ACTOR("monte_carlo_localizer", MonteCarloLocalizerActor,
                       MonteCarloLocalizerActorOptions,
                       "adaptive Monte Carlo localisation on a known map (scan + odom -> pose)");

}  // namespace tessera::localization
