#include <tessera/laser_slam/submap_builder_actor.hpp>

#include <tessera/actor_common/laser_scan.hpp>
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <stdexcept>
#include <string>

namespace tessera::laser_slam {
namespace {

Rbpf checkedFilter(const SubmapBuilderOptions& o) {
  const auto fail = [](const std::string& what) {
    throw ConfigError("rbpf_submap_builder: " + what);
  };
  if (!(std::isfinite(o.submap_distance) && o.submap_distance >= 0))
    fail("submap_distance must be >= 0 [m] (0 = never)");
  if (o.submap_scans < 0) fail("submap_scans must be >= 0 (0 = never)");
  if (o.scan_queue < 1 || o.odom_queue < 1 || o.scan_buffer < 1 || o.pose_history < 2)
    fail("scan_queue, odom_queue, scan_buffer must be >= 1 and pose_history >= 2");
  if (!(std::isfinite(o.max_pose_gap_s) && o.max_pose_gap_s > 0))
    fail("max_pose_gap_s must be > 0");
  if (o.frame_id.empty()) fail("frame_id must not be empty");
  if (o.loop_scan_every < 0)
    fail("loop_scan_every must be >= 0 (0 = off; got " + std::to_string(o.loop_scan_every) + ")");
  try {
    return Rbpf(o.rbpf);  // the core owns the rules for its options
  } catch (const std::invalid_argument& e) {
    fail(e.what());
  }
  throw std::logic_error("unreachable");
}

Eigen::Matrix3d rotateCovariance(const Eigen::Matrix3d& c, const tessera::Pose2& frame) {
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  r.topLeftCorner<2, 2>() = frame.rotation();
  return r * c * r.transpose();
}

}  // namespace

SubmapBuilderActor::SubmapBuilderActor(SubmapBuilderOptions options)
    : options_(std::move(options)),
      rbpf_(checkedFilter(options_)),
      pairing_(static_cast<std::size_t>(options_.scan_buffer),
               static_cast<std::size_t>(options_.pose_history), options_.max_pose_gap_s) {}

void SubmapBuilderActor::configure(ActorContext& ctx) {
  ctx.subscribe<msg::LaserScan>(
      "scan", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.scan_queue)),
      [this](const Message<msg::LaserScan>& m) { onScan(m); });
  ctx.subscribe<msg::Odometry>(
      "odom", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.odom_queue)),
      [this](const Message<msg::Odometry>& m) {
        onOdometry(m->getHeader().getStampNs(), toPose2(m->getPose()));
      });
  if (options_.camera_trigger) {
    ctx.subscribe<msg::CameraEvent>(
        "camera_events", MailboxPolicy::reliable(),
        [this](const Message<msg::CameraEvent>& m) { onCameraEvent(m); });
  }
  if (options_.optimized_poses) {
    ctx.subscribe<msg::SubmapPoses>(
        "submap_poses", MailboxPolicy::keepLatest(1),
        [this](const Message<msg::SubmapPoses>& m) { onSubmapPoses(m); });
  }
  pose_pub_ = ctx.advertise<msg::PoseStamped>("pose");
  correction_pub_ = ctx.advertise<msg::PoseStamped>("map_to_odom");
  chained_pub_ = ctx.advertise<msg::PoseStamped>("chained_pose");
  submap_pub_ = ctx.advertise<msg::Submap>("submaps");
  constraint_pub_ = ctx.advertise<msg::SubmapConstraint>("constraints");
  final_pub_ = ctx.advertise<msg::PoseStamped>("final_poses");
  if (options_.loop_scan_every > 0) loop_scan_pub_ = ctx.advertise<msg::LaserScan>("loop_scans");
}

void SubmapBuilderActor::onScan(const Message<msg::LaserScan>& scan) {
  ++scans_read_;
  pairing_.addItem(scan, scan->getHeader().getStampNs(),
                   [this](const auto& s, const tessera::Pose2& odom) { process(s, odom); });
}

void SubmapBuilderActor::onOdometry(Nanos stamp, const tessera::Pose2& pose) {
  if (!pairing_.addPose(stamp, pose,
                        [this](const auto& s, const tessera::Pose2& odom) { process(s, odom); }))
    ++odometry_invalid_;
}

void SubmapBuilderActor::onCameraEvent(const Message<msg::CameraEvent>& event) {
  if (!event->getEntered()) return;
  const int camera = event->getCameraId();
  if (camera == last_camera_) return;  // back in the view it just left: same submap
  last_camera_ = camera;
  handover_requested_ = true;
}

void SubmapBuilderActor::onSubmapPoses(const Message<msg::SubmapPoses>& poses) {
  // The newest submap the graph holds that this builder has started: the others follow it by
  // their chained hand-overs. A graph from another run (ids beyond ours) is ignored.
  int newest = -1;
  tessera::Pose2 origin;
  for (const auto& p : poses->getPoses()) {
    const auto id = static_cast<int>(p.getId());
    if (id >= static_cast<int>(chained_origins_.size()) || id < newest) continue;
    const tessera::Pose2 pose = toPose2(p.getPose());
    if (!pose.isFinite()) continue;
    newest = id;
    origin = pose;
  }
  if (newest < 0) return;
  optimized_id_ = newest;
  optimized_origin_ = origin;
  ++graph_updates_;
}

tessera::Pose2 SubmapBuilderActor::liveOrigin() const {
  if (optimized_id_ < 0) return submap_origin_;
  const auto& anchor = chained_origins_[static_cast<std::size_t>(optimized_id_)];
  return optimized_origin_ * (anchor.inverse() * submap_origin_);
}

void SubmapBuilderActor::process(const Message<msg::LaserScan>& scan, const tessera::Pose2& odom) {
  const Nanos stamp = scan->getHeader().getStampNs();
  const tessera::grid::RangeScan ranges = rangeScanOf(*scan);
  const tessera::Pose2 mount = laserMountOf(*scan);
  const RbpfStep step = rbpf_.addScan(nanosToSeconds(stamp), ranges, mount, odom);
  last_stamp_ = stamp;
  if (!rbpf_.initialized()) return;  // nothing to publish before the first usable scan
  // The motion the smoothed trajectory moves each scan by since its update: the odometry, or
  // with tracking the scan-matched motion of the online pose (continuous between updates;
  // an update's scan, where the online pose jumps to the filter's estimate, moves by odometry).
  const tessera::Pose2 online = rbpf_.pose();
  if (scan_odometry_.empty())
    scan_motion_ = odom;
  else if (step.updated || !options_.rbpf.track_between_updates)
    scan_motion_ = scan_motion_ * (last_odom_.inverse() * odom);
  else
    scan_motion_ = scan_motion_ * (last_online_.inverse() * online);
  last_odom_ = odom;
  last_online_ = online;
  scan_odometry_.push_back({stamp, scan_motion_});

  const bool by_distance =
      options_.submap_distance > 0 && rbpf_.submapTravelled() >= options_.submap_distance;
  const bool by_scans = options_.submap_scans > 0 &&
                        rbpf_.submapScans() >= static_cast<std::uint64_t>(options_.submap_scans);
  if (step.lost) {
    std::cerr << "[rbpf_submap_builder] lost in submap " << rbpf_.submapId() << ": "
              << options_.rbpf.lost_updates << " updates in a row matched at most "
              << static_cast<int>(100 * options_.rbpf.lost_match_fraction)
              << " % of the beams (last " << static_cast<int>(100 * step.match_fraction)
              << " %); submap " << rbpf_.submapId() + 1
              << " starts unanchored, placed by later constraints\n";
    handOver(stamp, /*lost=*/true);
  } else if (handover_requested_ || (step.updated && (by_distance || by_scans))) {
    if (handover_requested_) ++camera_handovers_;
    handover_requested_ = false;
    handOver(stamp);
  }
  publishPose(stamp, odom);
  if (options_.loop_scan_every > 0 &&
      ++loop_scan_count_ % static_cast<std::uint64_t>(options_.loop_scan_every) == 0)
    loop_scan_pub_.publish(scan);
}

void SubmapBuilderActor::publishPose(Nanos stamp, const tessera::Pose2& odometry) {
  const tessera::Pose2 origin = liveOrigin();
  const tessera::Pose2 local = rbpf_.pose();
  if (options_.optimized_poses && last_live_submap_ == rbpf_.submapId()) {
    // How far a new optimum moved the robot between two scans (same submap, so the filter's
    // own motion is not in it).
    const double jump =
        ((origin * local).translation() - (last_live_origin_ * local).translation()).norm();
    if (jump > 1e-9) ++live_corrections_;
    live_correction_max_m_ = std::max(live_correction_max_m_, jump);
  }
  last_live_origin_ = origin;
  last_live_submap_ = rbpf_.submapId();
  // The particle spread, once per scan: it walks every particle.
  const Eigen::Matrix3d spread = rbpf_.poseWithCovariance().covariance;
  const auto send = [&](Publisher<msg::PoseStamped>& pub, const tessera::Pose2& pose,
                        const Eigen::Matrix3d* cov) {
    auto loan = pub.loan();
    setHeader(loan->initHeader(), stamp, options_.frame_id, pub.nextSeq());
    writePose(loan->initPose(), pose, cov);
    pub.publish(std::move(loan));
  };
  const tessera::Pose2 global = origin * local;
  const Eigen::Matrix3d cov = rotateCovariance(spread, origin);
  send(pose_pub_, global, &cov);
  const Eigen::Matrix3d chained_cov = rotateCovariance(spread, submap_origin_);
  send(chained_pub_, submap_origin_ * local, &chained_cov);
  send(correction_pub_, global * odometry.inverse(), nullptr);
}

void SubmapBuilderActor::handOver(Nanos stamp, bool lost) {
  if (options_.keep_trajectory) appendBestTrajectory(finished_trajectory_);
  const std::vector<ScanPose> smoothed = densify(rbpf_.bestTrajectory());
  if (!options_.keep_trajectory && !scan_odometry_.empty()) {
    // The next submap's trajectory starts at this hand-over's scan: the motion chain before the
    // last scan at or before it is needed by nothing.
    const double at = nanosToSeconds(stamp) + 1e-6;
    auto keep = std::upper_bound(scan_odometry_.begin(), scan_odometry_.end(), at,
                                 [](double t, const ScanMotion& e) { return t < e.seconds(); });
    if (keep != scan_odometry_.begin()) --keep;
    scan_odometry_.erase(scan_odometry_.begin(), keep);
  }
  const FinishedSubmap done = lost ? rbpf_.startSubmapLost() : rbpf_.startSubmap();
  publishSubmap(done, stamp, smoothed);
  auto loan = constraint_pub_.loan();
  setHeader(loan->initHeader(), stamp, options_.frame_id, constraint_pub_.nextSeq());
  loan->setFromId(static_cast<std::uint32_t>(done.id));
  loan->setToId(static_cast<std::uint32_t>(done.id + 1));
  writePose(loan->initRelative(), done.next_in_this.pose, &done.next_in_this.covariance);
  loan->setKind(msg::SubmapConstraint::Kind::HAND_OVER);
  loan->setLost(lost);
  constraint_pub_.publish(std::move(loan));
  submap_origin_ = submap_origin_ * done.next_in_this.pose;
  chained_origins_.push_back(submap_origin_);
  last_online_ = rbpf_.pose();  // the next scan's tracked motion is in the new submap
}

void SubmapBuilderActor::publishSubmap(const FinishedSubmap& submap, Nanos stamp,
                                       const std::vector<ScanPose>& trajectory) {
  const tessera::grid::OccupancyMap map = submap.grid.toOccupancyMap();
  const std::size_t cells = map.cells.size();
  auto loan = submap_pub_.loan(cells + 40 * trajectory.size() + 1024);
  setHeader(loan->initHeader(), stamp, options_.frame_id, submap_pub_.nextSeq());
  loan->setId(static_cast<std::uint32_t>(submap.id));
  auto grid = loan->initGrid();
  setHeader(grid.initHeader(), stamp, "submap_" + std::to_string(submap.id), 0);
  grid.setResolution(static_cast<float>(map.resolution));
  grid.setWidth(static_cast<std::uint32_t>(map.width));
  grid.setHeight(static_cast<std::uint32_t>(map.height));
  writePose(grid.initOrigin(), map.origin);
  auto out = mutableViewInt8(grid.initCells(static_cast<unsigned>(cells)));
  std::copy(map.cells.begin(), map.cells.end(), out.begin());
  writePose(loan->initGlobalPose(), submap_origin_);
  loan->setScans(static_cast<std::uint32_t>(submap.scans_inserted));
  loan->setTravelledM(submap.travelled_m);
  loan->setFinished(true);
  auto poses = loan->initTrajectory(static_cast<unsigned>(trajectory.size()));
  for (unsigned i = 0; i < trajectory.size(); ++i) {
    poses[i].setStampNs(trajectory[i].stamp);
    poses[i].setX(trajectory[i].pose.x);
    poses[i].setY(trajectory[i].pose.y);
    poses[i].setTheta(trajectory[i].pose.theta);
  }
  submap_pub_.publish(std::move(loan));
  ++submaps_published_;
}

void SubmapBuilderActor::appendBestTrajectory(std::vector<Rbpf::StampedPose>& out) const {
  // A submap starts at the scan that ended the previous one: keep that stamp once.
  for (const auto& p : rbpf_.bestTrajectory())
    if (out.empty() || p.stamp_s > out.back().stamp_s)
      out.push_back({p.stamp_s, submap_origin_ * p.pose});
}

void SubmapBuilderActor::stop() {
  // Upstream has stopped: no odometry will come for scans still waiting.
  pairing_.finish();
  if (!rbpf_.initialized()) return;
  publishSubmap(rbpf_.currentSubmap(), last_stamp_, densify(rbpf_.bestTrajectory()));
  std::vector<Rbpf::StampedPose> trajectory = finished_trajectory_;
  appendBestTrajectory(trajectory);
  for (const auto& p : densify(trajectory)) {
    auto loan = final_pub_.loan();
    setHeader(loan->initHeader(), p.stamp, options_.frame_id, final_pub_.nextSeq());
    writePose(loan->initPose(), p.pose);
    final_pub_.publish(std::move(loan));
  }
}

std::vector<SubmapBuilderActor::ScanPose> SubmapBuilderActor::densify(
    const std::vector<Rbpf::StampedPose>& updates) const {
  // Every scan after the first update: the smoothed pose of the update before it, moved by the
  // odometry since (the online estimate does the same with the pose the filter had then).
  std::vector<ScanPose> out;
  out.reserve(scan_odometry_.size());
  std::size_t k = 0;     // next update to reach
  std::size_t scan = 0;  // scan_odometry_ index of the current update
  bool have_update = false;
  for (std::size_t i = 0; i < scan_odometry_.size(); ++i) {
    const double stamp = scan_odometry_[i].seconds();
    const tessera::Pose2& odom = scan_odometry_[i].motion;
    while (k < updates.size() && updates[k].stamp_s <= stamp + 1e-6) {
      // The update's own scan: the latest scan not after it.
      while (scan + 1 < scan_odometry_.size() &&
             scan_odometry_[scan + 1].seconds() <= updates[k].stamp_s + 1e-6)
        ++scan;
      have_update = true;
      ++k;
    }
    if (!have_update) continue;
    const Rbpf::StampedPose& base = updates[k - 1];
    const tessera::Pose2& base_odom = scan_odometry_[scan].motion;
    tessera::Pose2 pose = base.pose * (base_odom.inverse() * odom);
    if (options_.interpolate_updates && k < updates.size()) {
      // The next update's scan: its correction (map ⊕ odometry⁻¹) is where the odometry drift
      // since this update was found; blend toward it by time instead of jumping there.
      std::size_t next = scan;
      while (next + 1 < scan_odometry_.size() &&
             scan_odometry_[next + 1].seconds() <= updates[k].stamp_s + 1e-6)
        ++next;
      const double span = scan_odometry_[next].seconds() - scan_odometry_[scan].seconds();
      if (next > scan && span > 0) {
        const tessera::Pose2 from = base.pose * base_odom.inverse();
        const tessera::Pose2 to = updates[k].pose * scan_odometry_[next].motion.inverse();
        const double f = (stamp - scan_odometry_[scan].seconds()) / span;
        const tessera::Pose2 correction(from.x + f * (to.x - from.x), from.y + f * (to.y - from.y),
                                        from.theta + f * tessera::angleDiff(to.theta, from.theta));
        pose = correction * odom;
      }
    }
    out.push_back({scan_odometry_[i].stamp, pose});
  }
  return out;
}

void SubmapBuilderActor::summarize(Summary& out) const {
  const auto& s = rbpf_.stats();
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["scans_read"] = i64(scans_read_);
  out["scans_processed"] = i64(s.updates);
  out["particles"] = static_cast<std::int64_t>(rbpf_.particleCount());
  out["resamples"] = i64(s.resamples);
  out["match_failures"] = i64(s.match_failures);
  out["match_recoveries"] = i64(s.match_recoveries);
  if (s.tracked_scans > 0) {
    out["tracked_scans"] = i64(s.tracked_scans);
    out["tracking_failures"] = i64(s.tracking_failures);
    out["tracking_evaluations"] = i64(s.tracking_evaluations);
  }
  out["particle_updates"] = i64(s.particle_updates);
  out["coarse_evaluations"] = i64(s.coarse_evaluations);
  out["fine_evaluations"] = i64(s.fine_evaluations);
  out["submaps"] = i64(submaps_published_);
  out["scans_unpaired"] = i64(pairing_.unpaired());
  out["scans_unusable"] = i64(s.unusable_scans);
  // MiB, as peak_rss_mb and the other actors' memory figures.
  const std::size_t map_bytes = rbpf_.mapBytes();
  out["memory_mb"] = static_cast<double>(map_bytes) / (1024.0 * 1024.0);
  // The peak is sampled (RbpfStats::map_bytes_peak); the maps held now count too.
  out["memory_peak_mb"] =
      static_cast<double>(std::max(s.map_bytes_peak, map_bytes)) / (1024.0 * 1024.0);
  if (camera_handovers_ > 0) out["camera_handovers"] = i64(camera_handovers_);
  if (s.updates > 1) out["match_fraction_min"] = s.match_fraction_min;
  if (options_.rbpf.lost_match_fraction > 0) {
    out["suspect_updates"] = i64(s.suspect_updates);
    out["lost"] = i64(s.lost);
  }
  if (options_.optimized_poses) {
    out["graph_updates"] = i64(graph_updates_);
    out["live_corrections"] = i64(live_corrections_);
    out["live_correction_max_m"] = live_correction_max_m_;
  }
  if (odometry_invalid_ + s.invalid_odometry > 0)
    out["odometry_invalid"] = i64(odometry_invalid_ + s.invalid_odometry);
}

TESSERA_REGISTER_ACTOR("rbpf_submap_builder", SubmapBuilderActor, SubmapBuilderOptions,
                       "local laser SLAM: RBPF occupancy-grid submaps from scans and odometry");

}  // namespace tessera::laser_slam
