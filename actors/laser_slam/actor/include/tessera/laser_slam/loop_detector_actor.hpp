// loop_detector actor: loop closures for the global level of the two-level laser SLAM
// (docs/algorithms.md#submap-hand-over-and-loop-detection). Matches scans against
// finished submaps with the branch-and-bound CorrelativeMatcher and publishes each verified
// match as a revisit SubmapConstraint for the graph optimiser.
//
// Subscribes:
//   scan          msg::LaserScan        keep_latest(scan_queue)  the laser (with its mounting)
//   chained_pose  msg::PoseStamped      keep_latest(pose_queue)  the submap builder's estimate of
//                                                                 each scan (chained map frame)
//   constraints   msg::SubmapConstraint reliable, with publish_at_match: the builder's hand-overs
//                                       (where each new submap starts; other kinds ignored)
//   submaps       msg::Submap           reliable                 finished submaps: searched, and
//                                                                 the end of the current one
//   submap_poses  msg::SubmapPoses      keep_latest(1), with optimized_poses: where the graph
//                                       optimiser put the submaps (better search centres), and
//                                       the submaps lifelong mapping trimmed: forgotten here, with
//                                       the closures waiting to be published against them
//   ground_truth  msg::GroundTruthPose  keep_latest(1000), with score_ground_truth: scores every
//                                       accepted closure (simulation): loops_true/loops_false
// Publishes:
//   loop_constraints msg::SubmapConstraint  kind revisit, from the submap the robot was in to
//                                       the matched one. A match is published when the robot's
//                                       own submap is finished (its origin is known then; sent
//                                       at the builder's next pose, which follows its hand-over,
//                                       or at stop for the last submap), with the scan's smoothed
//                                       pose in it from the finished submap's trajectory: the
//                                       online estimate came from the particle
//                                       that was best then, which need not be the one whose map
//                                       the submap keeps. scanInTo carries the match itself (the
//                                       scan's pose in the matched submap, with its covariance)
//                                       for a scan-level graph.
//                                       With publish_at_match, a match made in the submap the
//                                       robot is in now is published at once, with the online
//                                       estimate of the scan in that submap (its origin chained
//                                       from the hand-overs): the live pose and the search
//                                       centres are corrected a submap earlier, while a
//                                       scan-level graph still ties the scan by its match.
//
// Search. Every `every_n_scans`-th scan with a pose is tried against the finished submaps whose
// area (expanded by the window) holds the robot's estimate, nearest first, skipping the
// `skip_recent` most recent ones (linked to the current one by hand-overs already). Of the
// verified matches, the best `closures_per_scan` are published. The window
// grows with the distance driven since the submap was finished (odometry-style drift):
// linear = min(window_linear_max, window_linear + window_growth · d), angular likewise. With
// window_since_closure, d counts from the last accepted closure too (whichever came later): a
// robot that keeps revisiting mapped space is re-anchored at each closure, so its windows stay
// small (lifelong mapping: fewer candidates, fewer chances of a false match).
// Verification (LoopClosureVerifier): score, ambiguity (second best / best), how well the scan
// pins the position (the match covariance's largest std: on the simulated office every false
// closure slid along a corridor or past a submap's edge with a std above 0.125 m, while 2/3 of
// the true ones were below 0.12 m), and the distance from the prior in units of window/3. Every
// decision is counted in the summary. Frames: submap grids in their own frame; robot poses in the
// chained map frame (builder) or the optimised one; constraint = pose of the matched submap's
// origin in the current submap's frame.
//
// Jumps (jump_check_distance > 0). An accepted closure places the robot in a submap; so does
// the next one. Between them the builder's chained pose gives the motion, accurate over a few
// metres. Within jump_check_distance metres driven of the last accepted closure, a verified match
// is rejected (loops_rejected_jump) when it puts the robot farther than jump_linear +
// jump_growth · d (or jump_angular + jump_angular_growth · d in heading) from where that closure
// and the motion since put it: in the same submap this needs nothing but the two matches and
// the motion; between two submaps it uses their optimised relative pose. A false match that
// slides along a corridor or into a look-alike room is a jump; a robot does not jump. Beyond
// the distance nothing is checked, so one false acceptance cannot lock true closures out.
//
// Memory. Each finished submap's int8 cells are kept zstd-compressed (grid::PackedOccupancyMap,
// lossless; ~14x smaller on the Intel submaps, 0.5 MB instead of 6.8 MB), which still grows with
// the explored area. The matcher's branch-and-bound pyramid (about 9 bytes per
// cell at depth 7: 8 levels of 1 byte plus padding) is built on demand and kept in an LRU cache
// of `pyramid_cache` submaps; a miss unpacks that one submap's cells into a temporary and
// rebuilds the pyramid from them. The build is deterministic, so the cache size changes the
// time spent, never a match. Summary: pyramid_builds, pyramid_cache_hits, pyramid_build_s
// (unpacking included; not part of loop_match_s), memory_mb (packed cells + cached pyramids at
// stop) and memory_peak_mb.
#pragma once

#include <tessera/msg/sensor.capnp.h>
#include <tessera/msg/submap.capnp.h>
#include <tessera/grid/occupancy_map.hpp>
#include <tessera/grid/packed_occupancy_map.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/scan_matching/correlative_matcher.hpp>
#include <tessera/scan_matching/scan_matcher.hpp>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace tessera::laser_slam {

struct LoopDetectorOptions {
  int every_n_scans = 5;
  int skip_recent = 1;
  int max_candidates = 3;
  int closures_per_scan = 1;
  double window_linear = 1.0;
  double window_growth = 0.01;
  double window_linear_max = 3.0;
  double window_angular = 0.3;
  double window_angular_growth = 0.005;
  double window_angular_max = 0.6;
  /// Submaps of loop closures are searched within a few metres and must agree well: a shorter
  /// range than the matcher's and a higher floor. Its max_range also limits the points
  /// prepared from each scan.
  tessera::scan_matching::CorrelativeMatcherOptions matcher = [] {
    tessera::scan_matching::CorrelativeMatcherOptions m;
    m.max_range = 20.0;
    m.min_score = 0.6;
    return m;
  }();
  /// A closure must score as well as the matcher's floor and be well constrained.
  tessera::scan_matching::LoopClosureVerifierOptions verifier = [] {
    tessera::scan_matching::LoopClosureVerifierOptions v;
    v.min_score = 0.6;
    v.max_position_sigma = 0.12;
    return v;
  }();
  /// Floors added to the matcher's covariance before publishing ([m], [rad] standard deviation):
  /// a match is only as exact as the submap it was made against.
  double sigma_floor_linear = 0.05;
  double sigma_floor_angular = 0.02;
  bool optimized_poses = false;
  bool publish_at_match = false;
  bool score_ground_truth = false;
  double truth_tolerance_linear = 0.5;
  double truth_tolerance_angular = 0.1;
  int scan_queue = 20;
  int pose_queue = 20;
  int pyramid_cache = 4;
  bool window_since_closure = false;
  double jump_check_distance = 0.0;
  double jump_linear = 0.3;
  double jump_growth = 0.02;
  double jump_angular = 0.1;
  double jump_angular_growth = 0.005;

  template <class V>
  void visit(V& v) {
    v("every_n_scans", every_n_scans, "try every n-th scan (>= 1)");
    v("skip_recent", skip_recent, "most recent finished submaps not searched (>= 0)");
    v("max_candidates", max_candidates, "submaps searched per scan, nearest first (>= 1)");
    v("closures_per_scan", closures_per_scan,
      "verified matches of one scan published, best first (1..max_candidates): more than one "
      "ties the scan to several submaps (for a scan-level graph)");
    v("window_linear", window_linear, "[m] search half-width right after a submap is finished");
    v("window_growth", window_growth, "[m per m driven] growth of the half-width");
    v("window_linear_max", window_linear_max, "[m] largest half-width");
    v("window_angular", window_angular, "[rad] heading half-width right after a submap");
    v("window_angular_growth", window_angular_growth, "[rad per m driven] its growth");
    v("window_angular_max", window_angular_max, "[rad] largest heading half-width");
    v("jump_check_distance", jump_check_distance,
      "[m] a match within this distance driven of the last accepted closure must agree with it "
      "and the motion since (0: off)");
    v("jump_linear", jump_linear, "[m] allowed disagreement right after the last closure");
    v("jump_growth", jump_growth, "[m per m driven] its growth");
    v("jump_angular", jump_angular, "[rad] allowed heading disagreement");
    v("jump_angular_growth", jump_angular_growth, "[rad per m driven] its growth");
    v("window_since_closure", window_since_closure,
      "grow the windows from the last accepted closure as well as from the submap's end "
      "(whichever is later)");
    v("matcher", matcher, "correlative scan matcher (branch and bound)");
    v("verifier", verifier, "which matches become loop closures");
    v("sigma_floor_linear", sigma_floor_linear, "[m] added to the published std (quadrature)");
    v("sigma_floor_angular", sigma_floor_angular, "[rad] added to the published std");
    v("optimized_poses", optimized_poses, "subscribe to submap_poses (graph_optimizer)");
    v("publish_at_match", publish_at_match,
      "publish a closure of the current submap when it is matched (online pose of the scan, "
      "origin from the hand-overs on constraints) instead of when the submap is finished");
    v("score_ground_truth", score_ground_truth,
      "subscribe to ground_truth and count accepted closures as true or false");
    v("truth_tolerance_linear", truth_tolerance_linear,
      "[m] a closure within this of the truth counts as true");
    v("truth_tolerance_angular", truth_tolerance_angular, "[rad] the same for heading");
    v("scan_queue", scan_queue, "scan mailbox size");
    v("pose_queue", pose_queue, "pose mailbox size");
    v("pyramid_cache", pyramid_cache,
      "matcher pyramids kept, least recently used evicted (>= 1); the others are rebuilt from "
      "the submap's cells when searched: same matches, ~9 bytes per cell each. 4 by "
      "measurement on the Intel log (carmen_global, up to 3 submaps per scan): 61 builds (20 "
      "if every pyramid were kept, 92 with 3, 393 with 2), +0.1 s beside ~2.1 s of matching, "
      "13 MB at most (packed cells and pyramids); 8 saves 17 builds for 10 MB more");
  }

  /// The flat keys of earlier versions, now inside the matcher and verifier groups.
  static constexpr RenamedKey kRenamedKeys[] = {
      {"max_range", "matcher.max_range"},
      {"min_score", "matcher.min_score and verifier.min_score"},
      {"pyramid_depth", "matcher.pyramid_depth"},
      {"max_ambiguity", "verifier.max_ambiguity"},
      {"max_position_sigma", "verifier.max_position_sigma"},
      {"max_prior_sigmas", "verifier.max_prior_sigmas"},
  };
};

class LoopDetectorActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit LoopDetectorActor(LoopDetectorOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  void summarize(Summary& out) const override;

  /// Where finished submap `id` is searched: its origin in the optimised frame (nullopt when it
  /// is not held).
  std::optional<tessera::Pose2> searchOrigin(int id) const;

 private:
  struct FinishedSubmap {
    int id = 0;
    // The grid as received, its cells compressed; pyramids are built from it.
    tessera::grid::PackedOccupancyMap cells;
    tessera::Pose2 chained;    // origin in the chained map frame (as published)
    tessera::Pose2 optimized;  // origin in the optimised frame (= chained until told)
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();  // grid centre in the submap frame
    double radius = 0.0;                               // [m] half-diagonal of the grid
    double driven_at_finish = 0.0;                     // [m] robot path length then
    Nanos start = 0, end = 0;                          // first and last scan stamps
    bool has_truth_origin = false;  // score_ground_truth: the true pose at `start`
    tessera::Pose2 truth_origin;
  };
  struct PendingClosure {
    Nanos stamp = 0;
    int matched = 0;               // submap the scan matched
    tessera::Pose2 in_matched;     // robot pose in that submap's frame (the match)
    tessera::Pose2 robot_chained;  // robot pose in the chained map frame (the builder's)
    Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // of in_matched
  };

  struct CachedPyramid {
    int id = 0;              // submap
    std::uint64_t used = 0;  // pyramid_clock_ at the last use
    std::optional<tessera::scan_matching::MatchGrid> grid;
  };

  void onScan(const Message<msg::LaserScan>& m);
  void onPose(const Message<msg::PoseStamped>& m);
  void pairScansWithPoses();
  void onSubmap(const Message<msg::Submap>& m);
  void onSubmapPoses(const Message<msg::SubmapPoses>& m);
  void onConstraint(const Message<msg::SubmapConstraint>& m);
  void onGroundTruth(const Message<msg::GroundTruthPose>& m);
  void tryScan(const Message<msg::LaserScan>& scan, const tessera::Pose2& robot_chained);
  /// `in_current`: the robot's pose in the current submap at the match.
  void publishClosure(const PendingClosure& c, int current, const tessera::Pose2& in_current);
  /// Publishes the closures a finished submap made ready (see ready_).
  void publishReady();
  bool truthAt(Nanos stamp, tessera::Pose2& out) const;
  /// With score_ground_truth: counts the closure as true or false.
  void scoreClosure(const PendingClosure& c);
  /// Search window for a submap: grows with the distance driven since it was finished.
  tessera::scan_matching::SearchWindow windowFor(const FinishedSubmap& s) const;
  /// The matcher pyramid of `s`, from the cache or built from its cells (evicting the least
  /// recently used one when the cache is full). Valid until the next call.
  const tessera::scan_matching::MatchGrid& pyramidFor(const FinishedSubmap& s);
  /// Bytes held now: packed submap cells and cached pyramids.
  std::size_t memoryBytes() const;
  void notePeak() { memory_peak_ = std::max(memory_peak_, memoryBytes()); }

  LoopDetectorOptions options_;
  tessera::scan_matching::ScanMatcher points_;  // only to turn scans into base-frame points
  tessera::scan_matching::CorrelativeMatcher matcher_;
  tessera::scan_matching::LoopClosureVerifier verifier_;
  Publisher<msg::SubmapConstraint> loop_pub_;
  std::vector<FinishedSubmap> submaps_;
  std::vector<CachedPyramid> pyramids_;  // at most pyramid_cache
  std::uint64_t pyramid_clock_ = 0, pyramid_builds_ = 0, pyramid_hits_ = 0;
  double pyramid_build_seconds_ = 0.0;
  std::size_t memory_peak_ = 0;                         // [bytes] largest memoryBytes() so far
  std::deque<Message<msg::LaserScan>> scans_;           // waiting for their pose
  std::deque<std::pair<Nanos, tessera::Pose2>> poses_;  // waiting for their scan
  std::vector<PendingClosure> pending_;  // matched, waiting for their own submap to end
  // Closures of a finished submap, published at the builder's next pose (stamped ready_after_ or
  // later) or at stop. The builder publishes that pose after its hand-over, so the optimiser
  // always receives the hand-over first, and the scan of that pose is searched with the poses
  // the graph had before these closures: the same order however the threads run.
  struct ReadyClosure {
    PendingClosure closure;
    int current = 0;
    tessera::Pose2 in_current;
  };
  std::vector<ReadyClosure> ready_;
  Nanos ready_after_ = 0;
  // publish_at_match: chained origins by submap id (the first submap's is the chained frame's
  // origin; later ones from hand-overs and finished submaps) and the newest submap started.
  std::map<int, tessera::Pose2> chained_origins_{{0, tessera::Pose2()}};
  int current_submap_ = 0;
  int last_finished_id_ = -1;
  std::map<int, tessera::Pose2> current_optimized_;  // optimised origins of unfinished submaps
  std::map<Nanos, tessera::Pose2> truth_;
  Nanos last_end_ = -1;  // last stamp of the newest finished submap
  Nanos first_stamp_ = -1;
  bool have_last_pose_ = false;
  tessera::Pose2 last_pose_;
  double driven_ = 0.0;
  double driven_at_closure_ = -1.0;  // [m] driven_ at the last accepted closure (-1: none)
  // The last accepted closure, for the jump check: matched submap, robot pose in it and in the
  // chained frame.
  struct LastClosure {
    int submap = -1;
    tessera::Pose2 in_matched, robot_chained;
  } last_closure_;
  /// True when a match of the robot in submap `s` at `in_matched` (chained pose
  /// `robot_chained`) disagrees with the last accepted closure and the motion since.
  bool isJump(const FinishedSubmap& s, const tessera::Pose2& in_matched,
              const tessera::Pose2& robot_chained) const;
  std::uint64_t rejected_jump_ = 0;
  std::uint64_t submaps_trimmed_ = 0, closures_dropped_trimmed_ = 0, submaps_drifted_ = 0;
  std::size_t trimmed_listed_ = 0;  // length of the last submap_poses.trimmed handled
  double submap_drift_max_ = 0.0;   // [m] score_ground_truth: worst submap trajectory vs truth
  std::uint64_t scans_seen_ = 0, scans_tried_ = 0, matches_run_ = 0, published_ = 0;
  std::uint64_t published_smoothed_ = 0;  // of published_: with the submap's smoothed scan pose
  std::uint64_t published_at_match_ = 0;  // of published_: at once (publish_at_match)
  std::uint64_t truth_true_ = 0, truth_false_ = 0, truth_unknown_ = 0, submaps_rejected_ = 0;
  double match_seconds_ = 0.0;
};

}  // namespace tessera::laser_slam
