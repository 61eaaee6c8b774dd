#include <tessera/laser_slam/map_merger_actor.hpp>

#include <tessera/actor_common/map_message.hpp>
#include <tessera/io/atomic_file.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/periodic.hpp>
#include <tessera/runtime/profile.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <set>
#include <stdexcept>

namespace tessera::laser_slam {
namespace map_merger_actor_detail {

MapMerger checkedMerger(const MapMergerActorOptions& o) {
  const auto fail = [](const std::string& what) { throw ConfigError("map_merger: " + what); };
  if (o.robots.size() < 2)
    fail("robots: need at least two robot namespaces (got " + std::to_string(o.robots.size()) +
         ")");
  std::set<std::string> seen;
  for (const auto& r : o.robots) {
    if (!isTopicNamespace(r))
      fail("robots: '" + r + "' is not a topic namespace (letters, digits, '_', inner '/')");
    if (!seen.insert(r).second) fail("robots: '" + r + "' is named twice");
  }
  if (!(std::isfinite(o.publish_period_s) && o.publish_period_s >= 0))
    fail("publish_period_s must be >= 0");
  if (o.frame_id.empty()) fail("frame_id must not be empty");
  if (!(std::isfinite(o.truth_tolerance_linear) && o.truth_tolerance_linear > 0 &&
        std::isfinite(o.truth_tolerance_angular) && o.truth_tolerance_angular > 0))
    fail("truth tolerances must be > 0");
  try {
    return MapMerger(static_cast<int>(o.robots.size()), o.merger);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(e.what());
  }
}

}  // namespace map_merger_actor_detail

MapMergerActor::MapMergerActor(MapMergerActorOptions options)
    : options_(std::move(options)),
      merger_(map_merger_actor_detail::checkedMerger(options_)),
      robots_(options_.robots.size()) {}

void MapMergerActor::configure(ActorContext& ctx) {
  output_dir_ = ctx.outputDir();
  map_pub_ = ctx.advertise<msg::OccupancyGrid>("map");
  for (std::size_t k = 0; k < options_.robots.size(); ++k) {
    const std::string& ns = options_.robots[k];
    const int robot = static_cast<int>(k);
    ctx.subscribe<msg::Submap>(
        ns + "/submaps", MailboxPolicy::reliable(),
        [this, robot](const Message<msg::Submap>& m) { onSubmap(robot, m); });
    if (options_.optimized_poses)
      ctx.subscribe<msg::SubmapPoses>(
          ns + "/submap_poses", MailboxPolicy::keepLatest(1),
          [this, robot](const Message<msg::SubmapPoses>& m) { onSubmapPoses(robot, m); });
    ctx.subscribe<msg::PoseStamped>(
        ns + "/pose", MailboxPolicy::keepLatest(10).asOptional(),
        [this, robot](const Message<msg::PoseStamped>& m) { onPose(robot, m); });
    ctx.subscribe<msg::PoseStamped>(
        ns + "/trajectory_final", MailboxPolicy::reliable().asOptional(),
        [this, robot](const Message<msg::PoseStamped>& m) {
          const tessera::Pose2 p = toPose2(m->getPose());
          if (p.isFinite())
            robots_[static_cast<std::size_t>(robot)].trajectory.emplace_back(
                m->getHeader().getStampNs(), p);
          else
            ++poses_invalid_;
        });
    if (options_.score_ground_truth)
      ctx.subscribe<msg::GroundTruthPose>(ns + "/ground_truth", MailboxPolicy::keepLatest(1000),
                                          [this, robot](const Message<msg::GroundTruthPose>& m) {
                                            const tessera::Pose2 p = toPose2(m->getPose());
                                            robots_[static_cast<std::size_t>(robot)].truth.add(
                                                m->getHeader().getStampNs(), p);
                                          });
    robots_[k].map_pose_pub = ctx.advertise<msg::PoseStamped>(ns + "/map_pose");
    robots_[k].trajectory_pub = ctx.advertise<msg::PoseStamped>(ns + "/trajectory_merged");
  }
  addPeriodicTimer(ctx, options_.publish_period_s, [this] {
    if (dirty_) publishMap();
  });
}

void MapMergerActor::onSubmap(int robot, const Message<msg::Submap>& m) {
  if (!m->getFinished()) return;
  RobotState& r = robots_[static_cast<std::size_t>(robot)];
  const int id = static_cast<int>(m->getId());
  tessera::grid::OccupancyMap grid;
  try {
    grid = toOccupancyMap(m->getGrid());
  } catch (const std::invalid_argument& e) {
    std::cerr << "[map_merger] " << options_.robots[static_cast<std::size_t>(robot)] << ": submap "
              << id << ": " << e.what() << "; left out\n";
    ++submaps_rejected_;
    return;
  }
  const tessera::Pose2 chained = toPose2(m->getGlobalPose());
  std::vector<SubmapTrajectoryPose> trajectory;
  for (const auto p : m->getTrajectory())
    trajectory.push_back({p.getStampNs(), tessera::Pose2(p.getX(), p.getY(), p.getTheta())});
  // Origin in the robot's optimised frame: its optimiser's, else moved like its newest one.
  tessera::Pose2 pose = chained;
  if (const auto it = r.optimized.find(id); it != r.optimized.end()) {
    pose = it->second;
  } else if (r.newest_optimized >= 0) {
    pose =
        r.optimized.at(r.newest_optimized) * r.chained.at(r.newest_optimized).inverse() * chained;
  }
  const std::string error = merger_.addSubmap(robot, id, std::move(grid), pose, trajectory);
  if (!error.empty()) {
    // Counted by the merger (merger_submaps_rejected adds both counts).
    std::cerr << "[map_merger] " << options_.robots[static_cast<std::size_t>(robot)] << ": "
              << error << "; left out\n";
    return;
  }
  r.chained[id] = chained;
  for (const auto& p : trajectory)
    if (p.pose.isFinite()) {
      r.first_pose.emplace(id, p);
      break;
    }
  if (r.optimized.count(id)) r.newest_optimized = std::max(r.newest_optimized, id);
  last_stamp_ = std::max(last_stamp_, m->getHeader().getStampNs());
  dirty_ = true;
  if (options_.score_ground_truth) scoreNewClosures();
}

void MapMergerActor::onSubmapPoses(int robot, const Message<msg::SubmapPoses>& m) {
  RobotState& r = robots_[static_cast<std::size_t>(robot)];
  for (const auto p : m->getPoses()) {
    const tessera::Pose2 pose = toPose2(p.getPose());
    const int id = static_cast<int>(p.getId());
    if (!pose.isFinite()) {
      ++poses_invalid_;
      continue;
    }
    r.optimized[id] = pose;
    merger_.setPose(robot, id, pose);
    if (r.chained.count(id)) r.newest_optimized = std::max(r.newest_optimized, id);
  }
  dirty_ = true;
}

void MapMergerActor::onPose(int robot, const Message<msg::PoseStamped>& m) {
  const tessera::Pose2 pose = toPose2(m->getPose());
  if (!pose.isFinite()) {
    ++poses_invalid_;
    return;
  }
  const auto frame = merger_.frame(robot);
  if (!frame) return;
  RobotState& r = robots_[static_cast<std::size_t>(robot)];
  auto loan = r.map_pose_pub.loan();
  setHeader(loan->initHeader(), m->getHeader().getStampNs(), options_.frame_id,
            r.map_pose_pub.nextSeq());
  writePose(loan->initPose(), *frame * pose);
  r.map_pose_pub.publish(std::move(loan));
  ++poses_published_;
}

void MapMergerActor::publishMap() {
  const tessera::grid::OccupancyMap map = merger_.assemble();
  dirty_ = false;
  if (map.empty()) return;
  publishOccupancyMap(map_pub_, map, last_stamp_, options_.frame_id);
  ++maps_published_;
}

bool MapMergerActor::truthAt(const RobotState& r, Nanos stamp, tessera::Pose2& out) const {
  const auto found = r.truth.at(stamp, out);
  return found == PoseHistory::Lookup::kExact || found == PoseHistory::Lookup::kInterpolated;
}

void MapMergerActor::scoreNewClosures() {
  const auto& closures = merger_.closures();
  for (; scored_ < closures.size(); ++scored_) {
    const InterRobotClosure& c = closures[scored_];
    const RobotState& a = robots_[static_cast<std::size_t>(c.robot_a)];
    const RobotState& b = robots_[static_cast<std::size_t>(c.robot_b)];
    // Truth of the patch (robot b at its stamp) in submap t's frame (robot a's origin of t).
    tessera::Pose2 patch_truth, first_truth;
    const auto first = a.first_pose.find(c.submap_a);
    if (first == a.first_pose.end() || !truthAt(b, c.patch_stamp_ns, patch_truth) ||
        !truthAt(a, first->second.stamp_ns, first_truth)) {
      ++truth_unknown_;
      continue;
    }
    const tessera::Pose2 origin_t = first_truth * first->second.pose.inverse();
    const tessera::Pose2 truth = origin_t.inverse() * patch_truth;
    const bool ok =
        std::hypot(truth.x - c.match.x, truth.y - c.match.y) <= options_.truth_tolerance_linear &&
        std::abs(tessera::angleDiff(truth.theta, c.match.theta)) <=
            options_.truth_tolerance_angular;
    ++(ok ? truth_true_ : truth_false_);
    if (!ok)
      std::cerr << "[map_merger] false inter-robot closure: " << options_.robots[c.robot_b]
                << " submap " << c.submap_b << " in " << options_.robots[c.robot_a] << " submap "
                << c.submap_a << "\n";
  }
}

bool MapMergerActor::truthFrame(int robot, tessera::Pose2& out) const {
  const RobotState& r = robots_[static_cast<std::size_t>(robot)];
  if (r.first_pose.empty()) return false;
  const auto& [id, first] = *r.first_pose.begin();
  const auto origin = merger_.submapPose(robot, id);
  tessera::Pose2 truth;
  if (!origin || !truthAt(r, first.stamp_ns, truth)) return false;
  // World pose of the submap's origin, then of the robot's frame that holds it at `origin`.
  out = truth * first.pose.inverse() * origin->inverse();
  return true;
}

void MapMergerActor::writeFrames() {
  // Written whole or not at all (io::AtomicFile): a reader never sees half a file.
  try {
    const std::filesystem::path path = std::filesystem::path(output_dir_) / options_.frames_file;
    io::AtomicFile file(path);
    std::ostream& out = file.stream();
    out << std::setprecision(9) << "{\n  \"frame_id\": \"" << options_.frame_id
        << "\",\n  \"reference\": \"" << options_.robots[0] << "\",\n  \"robots\": [\n";
    for (std::size_t k = 0; k < options_.robots.size(); ++k) {
      const auto frame = merger_.frame(static_cast<int>(k));
      std::size_t closures = 0;
      for (const auto& c : merger_.closures())
        closures += (c.robot_a == static_cast<int>(k) || c.robot_b == static_cast<int>(k));
      out << "    {\"name\": \"" << options_.robots[k]
          << "\", \"joined\": " << (frame ? "true" : "false");
      if (frame)
        out << ", \"x\": " << frame->x << ", \"y\": " << frame->y
            << ", \"theta\": " << frame->theta;
      out << ", \"closures\": " << closures << "}" << (k + 1 < options_.robots.size() ? "," : "")
          << "\n";
    }
    out << "  ]\n}\n";
    file.commit();
    frames_path_ = path.string();
  } catch (const std::exception& e) {
    write_error_ = e.what();
    std::cerr << "[map_merger] " << write_error_ << "\n";
  }
}

void MapMergerActor::stop() {
  publishMap();
  for (std::size_t k = 0; k < robots_.size(); ++k) {
    const auto frame = merger_.frame(static_cast<int>(k));
    if (!frame) continue;
    RobotState& r = robots_[k];
    std::sort(r.trajectory.begin(), r.trajectory.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& [stamp, pose] : r.trajectory) {
      auto loan = r.trajectory_pub.loan();
      setHeader(loan->initHeader(), stamp, options_.frame_id, r.trajectory_pub.nextSeq());
      writePose(loan->initPose(), *frame * pose);
      r.trajectory_pub.publish(std::move(loan));
    }
  }
  if (!options_.frames_file.empty() && !output_dir_.empty()) writeFrames();
}

void MapMergerActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  const MapMergerCounts& c = merger_.counts();
  std::int64_t joined = 0;
  for (int k = 0; k < merger_.robots(); ++k) joined += merger_.frame(k) ? 1 : 0;
  out["robots"] = i64(robots_.size());
  out["robots_joined"] = joined;  // the reference robot counts
  out["merger_submaps"] = i64(c.submaps);
  out["merger_submaps_rejected"] = i64(c.submaps_rejected + submaps_rejected_);
  out["merger_patches"] = i64(c.patches);
  out["merger_patches_sparse"] = i64(c.patches_sparse);
  out["merger_global_searches"] = i64(c.global_searches);
  out["merger_global_coarse_rejected"] = i64(c.global_coarse_rejected);
  out["merger_global_ambiguous"] = i64(c.global_ambiguous);
  out["merger_refined_rejected"] = i64(c.refined_rejected);
  out["merger_conflicting"] = i64(c.conflicting);
  out["merger_candidates"] = i64(c.candidates);
  out["merger_disagreeing"] = i64(c.disagreeing);
  out["merger_joined_searches"] = i64(c.joined_searches);
  out["merger_joined_rejected"] = i64(c.joined_rejected);
  out["merger_joins"] = i64(c.joins);
  const auto& v = merger_.verifierCounts();
  out["merger_rejected_no_match"] = i64(v.no_match);
  out["merger_rejected_low_score"] = i64(v.low_score);
  out["merger_rejected_unconstrained"] = i64(v.unconstrained);
  out["merger_rejected_inconsistent"] = i64(v.inconsistent);
  out["inter_robot_closures"] = i64(c.closures);
  out["merger_match_s"] = c.match_seconds;
  out["merger_memory_mb"] = static_cast<double>(merger_.bytes()) / (1024.0 * 1024.0);
  out["maps_published"] = i64(maps_published_);
  out["map_poses_published"] = i64(poses_published_);
  if (poses_invalid_ > 0) out["poses_invalid"] = i64(poses_invalid_);
  if (options_.score_ground_truth) {
    out["inter_robot_closures_true"] = i64(truth_true_);
    out["inter_robot_closures_false"] = i64(truth_false_);
    out["inter_robot_closures_unscored"] = i64(truth_unknown_);
    // How far each joined robot's frame is from where the truth puts it (reference: robot 0).
    tessera::Pose2 reference;
    double worst_linear = 0, worst_angular = 0;
    const bool have_reference = truthFrame(0, reference);
    for (int k = 1; k < merger_.robots(); ++k) {
      const auto frame = merger_.frame(k);
      tessera::Pose2 world;
      if (!frame || !have_reference || !truthFrame(k, world)) continue;
      const tessera::Pose2 truth = reference.inverse() * world;
      worst_linear = std::max(worst_linear, std::hypot(truth.x - frame->x, truth.y - frame->y));
      worst_angular =
          std::max(worst_angular, std::abs(tessera::angleDiff(truth.theta, frame->theta)));
    }
    out["frame_error_m"] = worst_linear;
    out["frame_error_rad"] = worst_angular;
  }
  if (!frames_path_.empty()) out["frames_path"] = frames_path_;
  if (!write_error_.empty()) out["frames_write_error"] = write_error_;
}

TESSERA_REGISTER_ACTOR("map_merger", MapMergerActor, MapMergerActorOptions,
                       "several robots' laser SLAM joined into one map: inter-robot closures, "
                       "each robot's frame and pose in the merged map");

}  // namespace tessera::laser_slam
