#include <tessera/line_slam/line_slam_actor.hpp>

#include <tessera/actor_common/laser_scan.hpp>
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace tessera::line_slam {
namespace {

const LineSlamActorOptions& checkedActorOptions(const LineSlamActorOptions& o) {
  const auto fail = [](const std::string& what) { throw ConfigError("line_slam: " + what); };
  if (!(std::isfinite(o.min_travel) && o.min_travel >= 0) ||
      !(std::isfinite(o.min_rotation) && o.min_rotation >= 0))
    fail("min_travel and min_rotation must be >= 0");
  if (o.map_every < 1) fail("map_every must be >= 1");
  if (o.scan_queue < 1 || o.odom_queue < 1 || o.scan_buffer < 1 || o.pose_history < 2)
    fail("scan_queue, odom_queue, scan_buffer must be >= 1 and pose_history >= 2");
  if (!(std::isfinite(o.max_pose_gap_s) && o.max_pose_gap_s > 0))
    fail("max_pose_gap_s must be > 0");
  if (o.frame_id.empty()) fail("frame_id must not be empty");
  return o;
}

/// The core built from its group; its errors start with the key, named here with the group.
template <class Core, class Opts>
Core checked(const Opts& o, const char* group) {
  try {
    return Core(o);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(std::string("line_slam: ") + group + "." + e.what());
  }
}

bool scanUsable(const msg::LaserScan::Reader& s) {
  if (!std::isfinite(s.getAngleMin()) || !std::isfinite(s.getAngleIncrement())) return false;
  const auto ranges = view<float>(s.getRanges());
  return std::any_of(ranges.begin(), ranges.end(), [](float r) { return std::isfinite(r); });
}

}  // namespace

LineSlamActor::LineSlamActor(LineSlamActorOptions options)
    : options_(checkedActorOptions(options)),
      extractor_(checked<tessera::line_slam::LineExtractor>(options_.extractor, "extractor")),
      slam_(checked<LineEkfSlam>(options_.ekf, "ekf")),
      pairing_(static_cast<std::size_t>(options_.scan_buffer),
               static_cast<std::size_t>(options_.pose_history), options_.max_pose_gap_s),
      truth_(static_cast<std::size_t>(options_.pose_history), options_.max_pose_gap_s) {}

void LineSlamActor::configure(ActorContext& ctx) {
  ctx.subscribe<msg::LaserScan>(
      "scan", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.scan_queue)),
      [this](const Message<msg::LaserScan>& m) { onScan(m); });
  ctx.subscribe<msg::Odometry>(
      "odom", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.odom_queue)),
      [this](const Message<msg::Odometry>& m) {
        onOdometry(m->getHeader().getStampNs(), toPose2(m->getPose()));
      });
  if (options_.ground_truth) {
    ctx.subscribe<msg::GroundTruthPose>(
        "ground_truth", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.odom_queue)),
        [this](const Message<msg::GroundTruthPose>& m) {
          truth_.add(m->getHeader().getStampNs(), toPose2(m->getPose()));
        });
  }
  pose_pub_ = ctx.advertise<msg::PoseStamped>("pose");
  map_pub_ = ctx.advertise<msg::LineMap>("line_map");
}

void LineSlamActor::onScan(const Message<msg::LaserScan>& scan) {
  ++scans_read_;
  if (!scanUsable(*scan)) {
    ++scans_rejected_;
    return;
  }
  pairing_.addItem(scan, scan->getHeader().getStampNs(),
                   [this](const auto& s, const tessera::Pose2& odom) { process(s, odom); });
}

void LineSlamActor::onOdometry(Nanos stamp, const tessera::Pose2& pose) {
  if (!pairing_.addPose(stamp, pose,
                        [this](const auto& s, const tessera::Pose2& odom) { process(s, odom); }))
    ++odometry_invalid_;
}

void LineSlamActor::process(const Message<msg::LaserScan>& scan, const tessera::Pose2& odom) {
  const Nanos stamp = scan->getHeader().getStampNs();
  ++scans_paired_;
  if (!last_odom_) {
    slam_.reset(odom);  // the map frame is the odometry frame at the first scan
  } else {
    slam_.predictOdometry(tessera::between(*last_odom_, odom));
  }
  last_odom_ = odom;

  bool update = !update_odom_;
  if (update_odom_) {
    const tessera::Pose2 moved = tessera::between(*update_odom_, odom);
    update = std::hypot(moved.x, moved.y) >= options_.min_travel ||
             std::abs(moved.theta) >= options_.min_rotation;
  }
  if (update) {
    update_odom_ = odom;
    const tessera::grid::RangeScan ranges = rangeScanOf(*scan);
    const tessera::Pose2 mount = laserMountOf(*scan);
    std::vector<tessera::line_slam::LineSegment> segments = extractor_.extract(ranges);
    for (auto& s : segments) s = tessera::line_slam::transformSegment(s, mount);
    segments_extracted_ += segments.size();
    slam_.update(segments);
    ++filter_updates_;
    if (filter_updates_ % static_cast<std::uint64_t>(options_.map_every) == 0) publishMap(stamp);
  }
  last_stamp_ = stamp;

  const tessera::Pose2 p = slam_.pose();
  const Eigen::Matrix3d cov = slam_.poseCovariance();
  auto loan = pose_pub_.loan();
  setHeader(loan->initHeader(), stamp, options_.frame_id, pose_pub_.nextSeq());
  writePose(loan->initPose(), tessera::Pose2{p.x, p.y, p.theta}, &cov);
  pose_pub_.publish(std::move(loan));
  if (options_.ground_truth) compareWithTruth(stamp);
}

void LineSlamActor::compareWithTruth(Nanos stamp) {
  tessera::Pose2 truth;
  const auto r = truth_.at(stamp, truth);
  if (r != tessera::PoseHistory::Lookup::kExact && r != tessera::PoseHistory::Lookup::kInterpolated)
    return;
  const tessera::Pose2 p = slam_.pose();
  final_position_error_ = std::hypot(p.x - truth.x, p.y - truth.y);
  final_heading_error_ =
      std::abs(tessera::angleDiff(p.theta, truth.theta)) * 180.0 / std::numbers::pi;
  max_position_error_ = std::max(max_position_error_, final_position_error_);
  ++truth_compared_;
}

void LineSlamActor::publishMap(Nanos stamp) {
  const auto lines = slam_.lines();
  auto loan = map_pub_.loan();
  setHeader(loan->initHeader(), stamp, options_.frame_id, map_pub_.nextSeq());
  auto out = loan->initLines(static_cast<unsigned>(lines.size()));
  for (unsigned i = 0; i < lines.size(); ++i) {
    const MapLine& l = lines[i];
    auto f = out[i];
    f.setId(l.id);
    f.setR(l.r);
    f.setPhi(l.phi);
    auto c = f.initCovariance(4);
    for (int k = 0; k < 4; ++k) c.set(static_cast<unsigned>(k), l.covariance(k / 2, k % 2));
    const Eigen::Vector2d a = l.p0(), b = l.p1();
    f.setX0(a.x());
    f.setY0(a.y());
    f.setX1(b.x());
    f.setY1(b.y());
    f.setObservations(static_cast<std::uint32_t>(l.observations));
  }
  loan->setTentative(static_cast<std::uint32_t>(slam_.tentativeCount()));
  map_pub_.publish(std::move(loan));
}

void LineSlamActor::stop() {
  pairing_.finish();
  if (last_odom_) publishMap(last_stamp_);
}

void LineSlamActor::summarize(Summary& out) const {
  const auto& s = slam_.stats();
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["scans_read"] = i64(scans_read_);
  out["scans_paired"] = i64(scans_paired_);
  out["scans_processed"] = i64(filter_updates_);
  out["scans_unpaired"] = i64(pairing_.unpaired());
  out["scans_rejected"] = i64(scans_rejected_);
  out["segments_extracted"] = i64(segments_extracted_);
  out["segments_rejected"] = i64(s.segments_rejected);
  out["segments_matched"] = i64(s.matched);
  out["segments_ambiguous"] = i64(s.ambiguous);
  out["lines"] = static_cast<std::int64_t>(slam_.lineCount());
  out["lines_added"] = i64(s.lines_added);
  out["lines_merged"] = i64(s.lines_merged);
  out["tentative_created"] = i64(s.tentative_created);
  out["tentative_promoted"] = i64(s.tentative_promoted);
  out["tentative_dropped"] = i64(s.tentative_dropped);
  out["association"] = detail::enumName(options_.ekf.association);
  const tessera::Pose2 p = slam_.pose();
  out["final_x"] = p.x;
  out["final_y"] = p.y;
  out["final_theta"] = p.theta;
  if (s.update_failures > 0) out["update_failures"] = i64(s.update_failures);
  if (odometry_invalid_ + s.motion_rejected > 0)
    out["odometry_invalid"] = i64(odometry_invalid_ + s.motion_rejected);
  if (options_.ground_truth && truth_compared_ > 0) {
    out["final_position_error_m"] = final_position_error_;
    out["final_heading_error_deg"] = final_heading_error_;
    out["max_position_error_m"] = max_position_error_;
  }
}

TESSERA_REGISTER_ACTOR("line_slam", LineSlamActor, LineSlamActorOptions,
                       "line-feature EKF SLAM (AIEPF lines) from scans and odometry");

}  // namespace tessera::line_slam
