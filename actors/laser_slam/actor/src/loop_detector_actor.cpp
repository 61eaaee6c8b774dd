#include <tessera/laser_slam/loop_detector_actor.hpp>

#include <tessera/actor_common/laser_scan.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <iterator>
#include <ranges>
#include <stdexcept>

namespace tessera::laser_slam {
namespace {

const LoopDetectorOptions& checked(const LoopDetectorOptions& o) {
  auto positive = [](double v) { return std::isfinite(v) && v > 0; };
  auto non_negative = [](double v) { return std::isfinite(v) && v >= 0; };
  if (o.every_n_scans < 1) throw ConfigError("loop_detector: every_n_scans must be >= 1");
  if (o.closures_per_scan < 1 || o.closures_per_scan > o.max_candidates)
    throw ConfigError("loop_detector: closures_per_scan must be in [1, max_candidates]");
  if (o.skip_recent < 0) throw ConfigError("loop_detector: skip_recent must be >= 0");
  if (o.max_candidates < 1) throw ConfigError("loop_detector: max_candidates must be >= 1");
  if (!positive(o.window_linear) || !positive(o.window_linear_max) ||
      o.window_linear_max < o.window_linear)
    throw ConfigError("loop_detector: need 0 < window_linear <= window_linear_max");
  if (!non_negative(o.window_angular) || !non_negative(o.window_angular_max) ||
      o.window_angular_max < o.window_angular)
    throw ConfigError("loop_detector: need 0 <= window_angular <= window_angular_max");
  if (!non_negative(o.window_growth) || !non_negative(o.window_angular_growth))
    throw ConfigError("loop_detector: window growth rates must be >= 0");
  if (!non_negative(o.sigma_floor_linear) || !non_negative(o.sigma_floor_angular))
    throw ConfigError("loop_detector: sigma floors must be >= 0");
  if (!non_negative(o.jump_check_distance) || !non_negative(o.jump_linear) ||
      !non_negative(o.jump_growth) || !non_negative(o.jump_angular) ||
      !non_negative(o.jump_angular_growth))
    throw ConfigError("loop_detector: jump_check_distance and the jump_* tolerances must be >= 0");
  if (!positive(o.truth_tolerance_linear) || !positive(o.truth_tolerance_angular))
    throw ConfigError("loop_detector: truth tolerances must be > 0");
  if (o.scan_queue < 1 || o.pose_queue < 1)
    throw ConfigError("loop_detector: scan_queue and pose_queue must be >= 1");
  if (o.pyramid_cache < 1)
    throw ConfigError("loop_detector: pyramid_cache must be >= 1 (pyramids kept; got " +
                      std::to_string(o.pyramid_cache) + ")");
  return o;
}

template <class Make>
auto configError(const char* what, Make make) {
  try {
    return make();
  } catch (const std::invalid_argument& e) {
    throw ConfigError(std::string("loop_detector: ") + what + ": " + e.what());
  }
}

tessera::scan_matching::ScanMatcher pointMaker(const LoopDetectorOptions& o) {
  tessera::scan_matching::ScanMatcherOptions m;
  m.max_range = o.matcher.max_range;  // points beyond the matcher's reach are not prepared
  return configError("max_range", [&] { return tessera::scan_matching::ScanMatcher(m); });
}

tessera::scan_matching::CorrelativeMatcher correlativeMatcher(const LoopDetectorOptions& o) {
  return configError("matcher",
                     [&] { return tessera::scan_matching::CorrelativeMatcher(o.matcher); });
}

tessera::scan_matching::LoopClosureVerifier verifier(const LoopDetectorOptions& o) {
  return configError("verifier",
                     [&] { return tessera::scan_matching::LoopClosureVerifier(o.verifier); });
}

/// Covariance of T = a ⊕ b⁻¹ from that of b, by a numeric Jacobian (the map is smooth and
/// 3-dimensional; a closed form buys nothing here).
Eigen::Matrix3d relativeCovariance(const tessera::Pose2& a, const tessera::Pose2& b,
                                   const Eigen::Matrix3d& cov_b) {
  const tessera::Pose2 t0 = a * b.inverse();
  Eigen::Matrix3d j;
  const double h = 1e-6;
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    d[k] = h;
    const tessera::Pose2 t = a * tessera::Pose2(b.x + d[0], b.y + d[1], b.theta + d[2]).inverse();
    j.col(k) = Eigen::Vector3d(t.x - t0.x, t.y - t0.y, tessera::angleDiff(t.theta, t0.theta)) / h;
  }
  return j * cov_b * j.transpose();
}

}  // namespace

LoopDetectorActor::LoopDetectorActor(LoopDetectorOptions options)
    : options_(checked(options)),
      points_(pointMaker(options_)),
      matcher_(correlativeMatcher(options_)),
      verifier_(verifier(options_)) {
  pyramids_.reserve(static_cast<std::size_t>(options_.pyramid_cache));
}

void LoopDetectorActor::configure(ActorContext& ctx) {
  ctx.subscribe<msg::LaserScan>(
      "scan", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.scan_queue)),
      [this](const Message<msg::LaserScan>& m) { onScan(m); });
  ctx.subscribe<msg::PoseStamped>(
      "chained_pose", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.pose_queue)),
      [this](const Message<msg::PoseStamped>& m) { onPose(m); });
  if (options_.publish_at_match)
    ctx.subscribe<msg::SubmapConstraint>(
        "constraints", MailboxPolicy::reliable(),
        [this](const Message<msg::SubmapConstraint>& m) { onConstraint(m); });
  ctx.subscribe<msg::Submap>("submaps", MailboxPolicy::reliable(),
                             [this](const Message<msg::Submap>& m) { onSubmap(m); });
  if (options_.optimized_poses)
    ctx.subscribe<msg::SubmapPoses>(
        "submap_poses", MailboxPolicy::keepLatest(1),
        [this](const Message<msg::SubmapPoses>& m) { onSubmapPoses(m); });
  if (options_.score_ground_truth)
    ctx.subscribe<msg::GroundTruthPose>(
        "ground_truth", MailboxPolicy::keepLatest(1000),
        [this](const Message<msg::GroundTruthPose>& m) { onGroundTruth(m); });
  loop_pub_ = ctx.advertise<msg::SubmapConstraint>("loop_constraints");
}

void LoopDetectorActor::onScan(const Message<msg::LaserScan>& m) {
  scans_.push_back(m);
  while (scans_.size() > static_cast<std::size_t>(options_.scan_queue)) scans_.pop_front();
  pairScansWithPoses();
}

void LoopDetectorActor::onPose(const Message<msg::PoseStamped>& m) {
  // The builder publishes a finished submap, its hand-over, then the pose of the same scan.
  if (m->getHeader().getStampNs() >= ready_after_) publishReady();
  const tessera::Pose2 pose = toPose2(m->getPose());
  if (!pose.isFinite()) return;
  poses_.emplace_back(m->getHeader().getStampNs(), pose);
  while (poses_.size() > static_cast<std::size_t>(options_.pose_queue)) poses_.pop_front();
  pairScansWithPoses();
}

void LoopDetectorActor::pairScansWithPoses() {
  // The builder stamps each pose with its scan's stamp; the two mailboxes may be served in
  // either order, so whichever comes first waits for the other.
  while (!scans_.empty() && !poses_.empty()) {
    const Nanos scan_stamp = scans_.front()->getHeader().getStampNs();
    const Nanos pose_stamp = poses_.front().first;
    if (scan_stamp < pose_stamp) {
      scans_.pop_front();  // a scan the builder gave no pose (skipped or unpaired)
      continue;
    }
    const tessera::Pose2 pose = poses_.front().second;
    poses_.pop_front();
    if (first_stamp_ < 0) first_stamp_ = pose_stamp;
    if (have_last_pose_) driven_ += std::hypot(pose.x - last_pose_.x, pose.y - last_pose_.y);
    last_pose_ = pose;
    have_last_pose_ = true;
    if (scan_stamp > pose_stamp) continue;  // its scan is gone (dropped); keep the path length
    const auto scan = scans_.front();
    scans_.pop_front();
    if (++scans_seen_ % static_cast<std::uint64_t>(options_.every_n_scans) == 0)
      tryScan(scan, pose);
  }
}

void LoopDetectorActor::tryScan(const Message<msg::LaserScan>& scan,
                                const tessera::Pose2& robot_chained) {
  const int searchable = static_cast<int>(submaps_.size()) - options_.skip_recent;
  if (searchable <= 0) return;
  ++scans_tried_;
  // The robot in the optimised frame: moved like the newest submap the graph has placed was
  // (the current one when its closures are published at once, else the newest finished one).
  const FinishedSubmap& newest = submaps_.back();
  tessera::Pose2 robot = newest.optimized * newest.chained.inverse() * robot_chained;
  if (const auto current = current_optimized_.find(current_submap_);
      current != current_optimized_.end() && current_submap_ > newest.id) {
    const auto chained = chained_origins_.find(current_submap_);
    if (chained != chained_origins_.end())
      robot = current->second * chained->second.inverse() * robot_chained;
  }
  struct Candidate {
    std::size_t index;
    double distance;
    tessera::Pose2 local;
  };
  std::vector<Candidate> candidates;
  for (int k = 0; k < searchable; ++k) {
    const auto& s = submaps_[static_cast<std::size_t>(k)];
    const tessera::Pose2 local = s.optimized.inverse() * robot;
    const double d = (local.translation() - s.centre).norm();
    if (d <= s.radius + windowFor(s).linear)
      candidates.push_back({static_cast<std::size_t>(k), d, local});
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.distance < b.distance; });
  if (candidates.size() > static_cast<std::size_t>(options_.max_candidates))
    candidates.resize(static_cast<std::size_t>(options_.max_candidates));
  if (candidates.empty()) return;

  const tessera::grid::RangeScan ranges = rangeScanOf(*scan);
  const tessera::Pose2 mount = laserMountOf(*scan);
  const tessera::scan_matching::ScanPoints prepared = points_.prepare(ranges, mount);
  std::vector<Eigen::Vector2d> points;
  points.reserve(prepared.size());
  for (const auto& p : prepared.endpoints) points.push_back(p.cast<double>());
  if (points.empty()) return;

  const auto start = std::chrono::steady_clock::now();
  const double build_seconds_before = pyramid_build_seconds_;
  std::vector<std::pair<double, PendingClosure>> accepted;  // by score
  for (const auto& c : candidates) {
    const auto& s = submaps_[c.index];
    const tessera::scan_matching::SearchWindow window = windowFor(s);
    const auto result = matcher_.match(pyramidFor(s), points, c.local, window);
    ++matches_run_;
    const Eigen::Vector3d sigma(window.linear / 3, window.linear / 3,
                                std::max(window.angular, 1e-3) / 3);
    const Eigen::Matrix3d prior = sigma.cwiseAbs2().asDiagonal();
    const auto verdict = verifier_.verify(result, c.local, prior);
    if (!verdict.accepted) continue;
    if (isJump(s, result.pose, robot_chained)) {
      ++rejected_jump_;
      continue;
    }
    accepted.push_back(
        {result.score,
         {scan->getHeader().getStampNs(), s.id, result.pose, robot_chained, result.covariance}});
  }
  // Matching only: the pyramids built on the way count in pyramid_build_s.
  match_seconds_ +=
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() -
      (pyramid_build_seconds_ - build_seconds_before);
  // Best first (the nearer submap on a tie). Closures beyond the best tie the scan to further
  // submaps; a scan-level graph uses each, a submap-level one fuses them.
  std::stable_sort(accepted.begin(), accepted.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  if (accepted.size() > static_cast<std::size_t>(options_.closures_per_scan))
    accepted.resize(static_cast<std::size_t>(options_.closures_per_scan));
  // A scan after the newest finished submap's last one was taken in the submap being built.
  const bool in_current = scan->getHeader().getStampNs() > last_end_;
  const auto origin = chained_origins_.find(current_submap_);
  const bool now = options_.publish_at_match && in_current && origin != chained_origins_.end();
  if (!accepted.empty()) {
    driven_at_closure_ = driven_;
    last_closure_ = {accepted.front().second.matched, accepted.front().second.in_matched,
                     robot_chained};
  }
  for (const auto& [score, closure] : accepted) {
    if (options_.score_ground_truth) scoreClosure(closure);
    if (now && closure.matched != current_submap_) {
      publishClosure(closure, current_submap_, origin->second.inverse() * closure.robot_chained);
      ++published_at_match_;
    } else {
      pending_.push_back(closure);
    }
  }
}

bool LoopDetectorActor::isJump(const FinishedSubmap& s, const tessera::Pose2& in_matched,
                               const tessera::Pose2& robot_chained) const {
  if (!(options_.jump_check_distance > 0) || last_closure_.submap < 0) return false;
  const double d = driven_ - driven_at_closure_;
  if (d > options_.jump_check_distance) return false;
  // The last closure's submap in this one's frame (identity for the same submap).
  tessera::Pose2 last_in_this;
  if (last_closure_.submap != s.id) {
    const auto last = std::find_if(submaps_.begin(), submaps_.end(),
                                   [&](const auto& x) { return x.id == last_closure_.submap; });
    if (last == submaps_.end()) return false;  // trimmed since: nothing to compare with
    last_in_this = s.optimized.inverse() * last->optimized;
  }
  const tessera::Pose2 predicted = last_in_this * last_closure_.in_matched *
                                   (last_closure_.robot_chained.inverse() * robot_chained);
  return std::hypot(predicted.x - in_matched.x, predicted.y - in_matched.y) >
             options_.jump_linear + options_.jump_growth * d ||
         std::abs(tessera::angleDiff(predicted.theta, in_matched.theta)) >
             options_.jump_angular + options_.jump_angular_growth * d;
}

void LoopDetectorActor::onConstraint(const Message<msg::SubmapConstraint>& m) {
  if (m->getKind() != msg::SubmapConstraint::Kind::HAND_OVER) return;
  const auto from = chained_origins_.find(static_cast<int>(m->getFromId()));
  const tessera::Pose2 relative = toPose2(m->getRelative());
  if (from == chained_origins_.end() || !relative.isFinite()) return;
  const int to = static_cast<int>(m->getToId());
  chained_origins_[to] = from->second * relative;
  current_submap_ = std::max(current_submap_, to);
}

void LoopDetectorActor::scoreClosure(const PendingClosure& c) {
  const auto& s = *std::find_if(submaps_.begin(), submaps_.end(),
                                [&](const auto& x) { return x.id == c.matched; });
  tessera::Pose2 now;
  if (s.has_truth_origin && truthAt(c.stamp, now)) {
    const tessera::Pose2 truth = s.truth_origin.inverse() * now;
    const bool ok = std::hypot(truth.x - c.in_matched.x, truth.y - c.in_matched.y) <=
                        options_.truth_tolerance_linear &&
                    std::abs(tessera::angleDiff(truth.theta, c.in_matched.theta)) <=
                        options_.truth_tolerance_angular;
    ++(ok ? truth_true_ : truth_false_);
    if (!ok && truth_false_ <= 10)
      std::cerr << "[loop_detector] false closure (by ground truth): scan at "
                << nanosToSeconds(c.stamp) << " s in submap " << c.matched << " at ("
                << c.in_matched.x << ", " << c.in_matched.y << ", " << c.in_matched.theta
                << "), truly at (" << truth.x << ", " << truth.y << ", " << truth.theta << ")\n";
  } else {
    ++truth_unknown_;
  }
}

tessera::scan_matching::SearchWindow LoopDetectorActor::windowFor(const FinishedSubmap& s) const {
  const double since = options_.window_since_closure
                           ? std::max(s.driven_at_finish, driven_at_closure_)
                           : s.driven_at_finish;
  const double driven = driven_ - since;
  return {std::min(options_.window_linear_max,
                   options_.window_linear + options_.window_growth * driven),
          std::min(options_.window_angular_max,
                   options_.window_angular + options_.window_angular_growth * driven)};
}

void LoopDetectorActor::onSubmap(const Message<msg::Submap>& m) {
  if (!m->getFinished()) return;
  const int id = static_cast<int>(m->getId());
  const auto g = m->getGrid();
  FinishedSubmap s;
  s.id = id;
  // The grid as received, checked here; kept packed (s.cells) once the submap is accepted.
  tessera::grid::OccupancyMap grid;
  grid.width = static_cast<int>(g.getWidth());
  grid.height = static_cast<int>(g.getHeight());
  grid.resolution = g.getResolution();
  grid.origin = toPose2(g.getOrigin());
  const auto cells = viewInt8(g.getCells());
  grid.cells.assign(cells.begin(), cells.end());
  s.chained = toPose2(m->getGlobalPose());
  const tessera::scan_matching::GridView view = tessera::scan_matching::GridView::of(grid);
  // Checked now, built when first searched (pyramidFor).
  const std::string grid_error = tessera::scan_matching::MatchGrid::check(view);
  if (s.chained.isFinite()) chained_origins_[id] = s.chained;
  const Nanos end = m->getHeader().getStampNs();
  const Nanos start = last_end_ >= 0 ? last_end_ : std::max<Nanos>(first_stamp_, 0);
  last_end_ = std::max(last_end_, end);
  // This submap's own scans ran up to `end`: their closures can be expressed now.
  const tessera::Pose2 chained = s.chained;
  const auto trajectory = m->getTrajectory();  // by increasing stamp
  // The smoothed pose of the scan at `stamp` (stamps went through seconds: 1 us tolerance).
  auto smoothed = [&](Nanos stamp, tessera::Pose2& out) {
    // Cap'n Proto 0.9 list iterators are not random access: search the indices.
    const auto indices = std::views::iota(0u, trajectory.size());
    const auto at = std::ranges::partition_point(
        indices, [&](unsigned k) { return trajectory[k].getStampNs() < stamp - 1000; });
    if (at == indices.end()) return false;
    const auto p = trajectory[*at];
    if (std::abs(p.getStampNs() - stamp) > 1000) return false;
    out = {p.getX(), p.getY(), p.getTheta()};
    return out.isFinite();
  };
  std::vector<PendingClosure> still;
  for (const auto& c : pending_) {
    if (c.stamp <= end && chained.isFinite()) {
      tessera::Pose2 in_current;
      if (smoothed(c.stamp, in_current)) {
        if (c.matched != id) ++published_smoothed_;
      } else {
        in_current = chained.inverse() * c.robot_chained;  // the online estimate
      }
      ready_.push_back({c, id, in_current});
    } else {
      still.push_back(c);
    }
  }
  pending_ = std::move(still);
  ready_after_ = end;
  if (!grid_error.empty() || !chained.isFinite()) {
    std::cerr << "[loop_detector] submap " << id << " cannot be searched: "
              << (!grid_error.empty() ? grid_error : "non-finite global pose") << "\n";
    ++submaps_rejected_;
    return;
  }
  // Searched where the graph last put it (as the submap being built), else chained from the
  // newest finished submap's optimised origin: never at its chained origin, which drifts from
  // the optimised frame lap after lap (only the very first submaps share the two frames).
  if (const auto placed = current_optimized_.find(id); placed != current_optimized_.end())
    s.optimized = placed->second;
  else if (!submaps_.empty() && submaps_.back().id < id)
    s.optimized = submaps_.back().optimized * (submaps_.back().chained.inverse() * chained);
  else
    s.optimized = chained;
  const double half_w = 0.5 * view.width * view.resolution,
               half_h = 0.5 * view.height * view.resolution;
  s.centre = view.origin * Eigen::Vector2d(half_w, half_h);
  s.radius = std::hypot(half_w, half_h);
  s.driven_at_finish = driven_;
  last_finished_id_ = std::max(last_finished_id_, id);
  current_optimized_.erase(current_optimized_.begin(), current_optimized_.upper_bound(id));
  s.start = start;
  s.end = end;
  if (options_.score_ground_truth) {
    s.has_truth_origin = truthAt(start, s.truth_origin);
    // How far the submap's own trajectory strays from the truth (both from its start): a
    // closure into a submap the local SLAM distorted is judged against a wrong frame.
    double drift = 0.0;
    for (const auto p : trajectory) {
      tessera::Pose2 truth;
      if (!s.has_truth_origin || !truthAt(p.getStampNs(), truth)) continue;
      const tessera::Pose2 rel = s.truth_origin.inverse() * truth;
      drift = std::max(drift, std::hypot(rel.x - p.getX(), rel.y - p.getY()));
    }
    submap_drift_max_ = std::max(submap_drift_max_, drift);
    if (drift > options_.truth_tolerance_linear) {
      ++submaps_drifted_;
      std::cerr << "[loop_detector] submap " << id << " strays " << drift
                << " m from the truth inside itself\n";
    }
    // Truth is needed from the current submap's start on (its origin, its closures' scans).
    truth_.erase(truth_.begin(), truth_.lower_bound(last_end_ - 1'000'000'000));
  }
  s.cells = tessera::grid::PackedOccupancyMap(grid);  // consistent: checked above
  submaps_.push_back(std::move(s));
  notePeak();
}

const tessera::scan_matching::MatchGrid& LoopDetectorActor::pyramidFor(const FinishedSubmap& s) {
  ++pyramid_clock_;
  for (auto& p : pyramids_)
    if (p.id == s.id) {
      p.used = pyramid_clock_;
      ++pyramid_hits_;
      return *p.grid;
    }
  // A miss takes a free slot, else the least recently used one, whose pyramid is freed before
  // the new one is built: at most pyramid_cache pyramids at any time. (Rebuilding in place in
  // the old one's storage was tried: submap sizes vary, so every slot grew to the largest, 60%
  // more memory, with no lower RSS on the Intel log.)
  CachedPyramid* slot = nullptr;
  if (pyramids_.size() < static_cast<std::size_t>(options_.pyramid_cache)) {
    slot = &pyramids_.emplace_back();
  } else {
    slot = &*std::min_element(pyramids_.begin(), pyramids_.end(),
                              [](const auto& a, const auto& b) { return a.used < b.used; });
    slot->grid.reset();
  }
  const auto start = std::chrono::steady_clock::now();
  {
    // Unpacked for the build only (counted in pyramid_build_s): one submap's cells at a time.
    const tessera::grid::OccupancyMap cells = s.cells.unpack();
    slot->grid.emplace(matcher_.precompute(tessera::scan_matching::GridView::of(cells)));
  }
  pyramid_build_seconds_ +=
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ++pyramid_builds_;
  slot->id = s.id;
  slot->used = pyramid_clock_;
  notePeak();
  return *slot->grid;
}

std::size_t LoopDetectorActor::memoryBytes() const {
  std::size_t total = 0;
  for (const auto& s : submaps_) total += s.cells.bytes();
  for (const auto& p : pyramids_)
    if (p.grid) total += p.grid->bytes();
  return total;
}

void LoopDetectorActor::publishReady() {
  for (const auto& r : ready_) publishClosure(r.closure, r.current, r.in_current);
  ready_.clear();
}

void LoopDetectorActor::stop() {
  publishReady();  // those of the last submap, which no hand-over follows
}

void LoopDetectorActor::publishClosure(const PendingClosure& c, int current,
                                       const tessera::Pose2& in_current) {
  if (c.matched == current) return;
  // The matched submap's origin seen from the current one's: robot-in-current ⊕ robot-in-matched⁻¹.
  const tessera::Pose2 relative = in_current * c.in_matched.inverse();
  const Eigen::Vector3d floor(options_.sigma_floor_linear * options_.sigma_floor_linear,
                              options_.sigma_floor_linear * options_.sigma_floor_linear,
                              options_.sigma_floor_angular * options_.sigma_floor_angular);
  Eigen::Matrix3d cov = relativeCovariance(in_current, c.in_matched, c.covariance);
  cov.diagonal() += floor;
  Eigen::Matrix3d match_cov = c.covariance;
  match_cov.diagonal() += floor;
  auto loan = loop_pub_.loan();
  setHeader(loan->initHeader(), c.stamp, "map", loop_pub_.nextSeq());
  loan->setFromId(static_cast<std::uint32_t>(current));
  loan->setToId(static_cast<std::uint32_t>(c.matched));
  writePose(loan->initRelative(), tessera::Pose2{relative.x, relative.y, relative.theta}, &cov);
  loan->setKind(msg::SubmapConstraint::Kind::REVISIT);
  writePose(loan->initScanInTo(),
            tessera::Pose2{c.in_matched.x, c.in_matched.y, c.in_matched.theta}, &match_cov);
  loop_pub_.publish(std::move(loan));
  ++published_;
}

void LoopDetectorActor::onSubmapPoses(const Message<msg::SubmapPoses>& m) {
  // The list is cumulative: only a message that lists more (or, from a restarted optimiser,
  // fewer) submaps than the last one can name a new trim.
  if (m->hasTrimmed() && m->getTrimmed().size() != trimmed_listed_) {
    trimmed_listed_ = m->getTrimmed().size();
    const auto trimmed = m->getTrimmed();
    const auto is_trimmed = [&](int id) {
      for (const auto t : trimmed)
        if (static_cast<int>(t) == id) return true;
      return false;
    };
    const std::size_t before = submaps_.size();
    std::erase_if(submaps_, [&](const FinishedSubmap& s) { return is_trimmed(s.id); });
    submaps_trimmed_ += before - submaps_.size();
    if (before != submaps_.size()) {
      std::erase_if(pyramids_, [&](const CachedPyramid& p) { return is_trimmed(p.id); });
      for (auto it = chained_origins_.begin(); it != chained_origins_.end();)
        it = is_trimmed(it->first) && it->first != current_submap_ ? chained_origins_.erase(it)
                                                                   : std::next(it);
    }
    const std::size_t waiting = pending_.size() + ready_.size();
    std::erase_if(pending_, [&](const PendingClosure& c) { return is_trimmed(c.matched); });
    std::erase_if(ready_, [&](const ReadyClosure& r) { return is_trimmed(r.closure.matched); });
    closures_dropped_trimmed_ += waiting - pending_.size() - ready_.size();
  }
  for (const auto p : m->getPoses()) {
    const tessera::Pose2 pose = toPose2(p.getPose());
    if (!pose.isFinite()) continue;
    for (auto& s : submaps_)
      if (s.id == static_cast<int>(p.getId())) s.optimized = pose;
    if (options_.publish_at_match && static_cast<int>(p.getId()) > last_finished_id_)
      current_optimized_[static_cast<int>(p.getId())] = pose;
  }
}

void LoopDetectorActor::onGroundTruth(const Message<msg::GroundTruthPose>& m) {
  const tessera::Pose2 p = toPose2(m->getPose());
  if (p.isFinite()) truth_[m->getHeader().getStampNs()] = p;
}

bool LoopDetectorActor::truthAt(Nanos stamp, tessera::Pose2& out) const {
  // Linear interpolation between the neighbouring truth poses (at most 0.5 s apart).
  const auto after = truth_.lower_bound(stamp);
  if (after == truth_.end()) return false;
  if (after->first == stamp || after == truth_.begin()) {
    if (std::abs(after->first - stamp) > 500'000'000) return false;
    out = after->second;
    return true;
  }
  const auto before = std::prev(after);
  if (after->first - before->first > 500'000'000) return false;
  const double f = static_cast<double>(stamp - before->first) /
                   static_cast<double>(after->first - before->first);
  const tessera::Pose2& a = before->second;
  const tessera::Pose2& b = after->second;
  out = {a.x + f * (b.x - a.x), a.y + f * (b.y - a.y),
         a.theta + f * tessera::angleDiff(b.theta, a.theta)};
  return true;
}

std::optional<tessera::Pose2> LoopDetectorActor::searchOrigin(int id) const {
  for (const auto& s : submaps_)
    if (s.id == id) return s.optimized;
  return std::nullopt;
}

void LoopDetectorActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  const auto& c = verifier_.counts();
  out["loop_scans_tried"] = i64(scans_tried_);
  out["loop_matches_run"] = i64(matches_run_);
  out["loop_match_s"] = match_seconds_;
  out["pyramid_builds"] = i64(pyramid_builds_);
  out["pyramid_cache_hits"] = i64(pyramid_hits_);
  out["pyramid_build_s"] = pyramid_build_seconds_;
  out["memory_mb"] = static_cast<double>(memoryBytes()) / (1024.0 * 1024.0);  // MiB, as peak_rss_mb
  out["memory_peak_mb"] = static_cast<double>(memory_peak_) / (1024.0 * 1024.0);
  out["loops_accepted"] = i64(c.accepted);
  out["submaps_searched"] = i64(submaps_.size());
  if (options_.score_ground_truth) {
    out["submap_drift_max_m"] = submap_drift_max_;
    out["submaps_drifted"] = i64(submaps_drifted_);
  }
  if (submaps_trimmed_ > 0) out["submaps_trimmed"] = i64(submaps_trimmed_);
  if (closures_dropped_trimmed_ > 0)
    out["closures_dropped_trimmed"] = i64(closures_dropped_trimmed_);
  out["loops_published"] = i64(published_);
  out["loops_published_smoothed"] = i64(published_smoothed_);
  if (options_.publish_at_match) out["loops_published_at_match"] = i64(published_at_match_);
  out["loops_rejected_no_match"] = i64(c.no_match);
  out["loops_rejected_low_score"] = i64(c.low_score);
  out["loops_rejected_ambiguous"] = i64(c.ambiguous);
  out["loops_rejected_unconstrained"] = i64(c.unconstrained);
  out["loops_rejected_inconsistent"] = i64(c.inconsistent);
  if (options_.jump_check_distance > 0) out["loops_rejected_jump"] = i64(rejected_jump_);
  out["loops_unpublished"] = i64(pending_.size());
  if (submaps_rejected_ > 0) out["loop_submaps_rejected"] = i64(submaps_rejected_);
  if (options_.score_ground_truth) {
    out["loops_true"] = i64(truth_true_);
    out["loops_false"] = i64(truth_false_);
    out["loops_unscored"] = i64(truth_unknown_);
    const auto scored = truth_true_ + truth_false_;
    out["loop_precision"] = scored > 0 ? static_cast<double>(truth_true_) / scored : 1.0;
  }
}

TESSERA_REGISTER_ACTOR("loop_detector", LoopDetectorActor, LoopDetectorOptions,
                       "loop closures: scans matched against finished submaps (branch and "
                       "bound), verified, published as revisit constraints");

}  // namespace tessera::laser_slam
