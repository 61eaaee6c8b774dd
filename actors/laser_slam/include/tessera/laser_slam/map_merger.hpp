// MapMerger: several robots' two-level SLAM maps joined into one frame
// (docs/algorithms.md#several-robots-one-map).
//
// Each robot keeps its own submaps, pose graph and frame (where its SLAM started); the robots do
// not know where they are relative to each other. MapMerger finds inter-robot closures: places
// of one robot's finished submap found in another robot's finished submaps. A place is a patch:
// the occupied cells of submap s within `patch_radius` of a pose of s's trajectory (every
// `patch_spacing` metres along it), in the frame of that pose. While two robots are not joined,
// each patch of a new submap is searched everywhere in each of the other robot's submaps, at
// every heading, on a coarse copy of the grid (cells max-pooled `coarse_factor` × `coarse_factor`,
// CorrelativeMatcher, branch and bound), must be unambiguous there (second best / best), and is
// refined at full resolution and verified (LoopClosureVerifier: score, how well it pins the
// position). Each such match says where robot b's frame lies in robot a's:
//   D_ab = pose_a(t) ⊕ match ⊕ patch⁻¹ ⊕ pose_b(s)⁻¹
// (pose_k: a submap's origin in its robot's frame, as that robot's optimiser has it now; match:
// the patch's pose in submap t; patch: its pose in submap s). One match may be a look-alike
// place, so two robots are joined only when `min_agreeing` matches of different patches agree on
// D_ab (within agree_linear / agree_angular); the others stay candidates. Once joined, each new
// submap's patches are searched near where D_ab puts them (a small window) and a verified match
// adds to the pair's closures. The pair's D_ab is the mean of its closures' estimates, recomputed
// from the robots' current submap poses, so it follows each robot's own optimisation.
//
// Frames: robot 0 is the reference; a robot joined to it (directly or through others) has
// frame(k) = pose of its frame in robot 0's, the merged frame. Submap grids are in their own
// frame; metres, radians. The merged map draws every joined robot's submaps at
// frame(k) ⊕ pose_k (MapAssembler).
//
// Cost: the global search runs the coarse matcher for every (patch, other robot's submap) pair
// until the robots are joined, over TBB workers; afterwards a few small windows per patch.
// Memory: each submap's cells zstd-packed (in the MapAssembler), its coarse pyramid, and
// full-resolution pyramids of `fine_cache` submaps (rebuilt on demand, deterministic).
// Plain C++ over Eigen; not thread-safe (one actor owns it).
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>
#include <tessera/laser_slam/map_assembler.hpp>
#include <tessera/scan_matching/correlative_matcher.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace tessera::laser_slam {

struct MapMergerOptions {
  double patch_spacing = 4.0;   ///< [m] of trajectory between two patches of a submap
  double patch_radius = 8.0;    ///< [m] occupied cells this close to the patch pose
  int min_patch_points = 200;   ///< patches with fewer occupied cells are not searched
  int max_patch_points = 1500;  ///< more are thinned evenly
  int occupied_percent = 65;    ///< a cell at least this occupied is a patch point
  int coarse_factor = 4;        ///< coarse cells are this many cells wide
  /// Global search on the coarse grids: a window over the whole submap, every heading.
  tessera::scan_matching::CorrelativeMatcherOptions coarse = [] {
    tessera::scan_matching::CorrelativeMatcherOptions m;
    m.pyramid_depth = 5;
    m.min_score = 0.5;
    m.max_range = 12.0;
    m.exclusion_radius = 1.5;
    m.exclusion_angle = 0.35;
    return m;
  }();
  double coarse_max_ambiguity = 0.9;  ///< second best / best on the coarse grid
  /// Refinement at full resolution, and the search once joined.
  tessera::scan_matching::CorrelativeMatcherOptions fine = [] {
    tessera::scan_matching::CorrelativeMatcherOptions m;
    m.pyramid_depth = 3;
    m.min_score = 0.5;
    m.max_range = 12.0;
    m.compute_second_best = false;
    return m;
  }();
  tessera::scan_matching::LoopClosureVerifierOptions verifier = [] {
    tessera::scan_matching::LoopClosureVerifierOptions v;
    v.min_score = 0.55;
    v.max_position_sigma = 0.12;
    v.max_prior_sigmas = 3.0;
    return v;
  }();
  double refine_window_linear = 0.5;    ///< [m] around the coarse match
  double refine_window_angular = 0.08;  ///< [rad]
  double joined_window_linear = 1.0;    ///< [m] around the prediction once joined
  double joined_window_angular = 0.1;   ///< [rad]
  int joined_candidates = 2;            ///< submaps searched per patch once joined
  /// A global match overlays the two submaps: occupied cells of either on the other's known free
  /// space (a cell of slack) are conflicts; above this fraction of the overlapping occupied
  /// cells the match is a look-alike (a mirrored corridor, a door where the other has a wall).
  double max_conflict_fraction = 0.02;
  int free_percent = 25;        ///< a cell less occupied than this is free
  int min_agreeing = 2;         ///< matches that must agree to join two robots
  double agree_linear = 0.4;    ///< [m] agreement of two D_ab estimates
  double agree_angular = 0.05;  ///< [rad]
  int fine_cache = 8;           ///< full-resolution pyramids kept

  template <class V>
  void visit(V& v) {
    v("patch_spacing", patch_spacing, "[m] of a submap's trajectory between two patches");
    v("patch_radius", patch_radius, "[m] radius of a patch around its trajectory pose");
    v("min_patch_points", min_patch_points, "patches with fewer occupied cells are skipped");
    v("max_patch_points", max_patch_points, "points of a patch beyond this are thinned evenly");
    v("occupied_percent", occupied_percent, "cells at least this occupied are patch points");
    v("coarse_factor", coarse_factor, "coarse grid cells are this many cells wide (>= 1)");
    v("coarse", coarse, "global search on the coarse grids (window: the whole submap)");
    v("coarse_max_ambiguity", coarse_max_ambiguity,
      "second best / best of the global search above which a place is ambiguous, (0, 1]");
    v("fine", fine, "full-resolution refinement and the search once joined");
    v("verifier", verifier, "which refined matches become inter-robot closures");
    v("refine_window_linear", refine_window_linear, "[m] refinement half-width");
    v("refine_window_angular", refine_window_angular, "[rad] refinement heading half-width");
    v("joined_window_linear", joined_window_linear, "[m] half-width of the search once joined");
    v("joined_window_angular", joined_window_angular, "[rad] its heading half-width");
    v("joined_candidates", joined_candidates, "submaps searched per patch once joined (>= 1)");
    v("max_conflict_fraction", max_conflict_fraction,
      "global matches whose overlaid submaps put more than this fraction of their occupied "
      "cells on the other's free space are rejected, [0, 1]");
    v("free_percent", free_percent, "cells less occupied than this are free (conflict check)");
    v("min_agreeing", min_agreeing,
      "matches of different patches that must agree before two robots are joined (>= 1)");
    v("agree_linear", agree_linear, "[m] two estimates of a robot's frame agree within this");
    v("agree_angular", agree_angular, "[rad] and within this heading");
    v("fine_cache", fine_cache, "full-resolution pyramids kept (>= 1)");
  }
};

/// An inter-robot closure: submap s of robot b found in submap t of robot a.
struct InterRobotClosure {
  int robot_a = 0, submap_a = 0;  ///< t
  int robot_b = 0, submap_b = 0;  ///< s
  tessera::Pose2 patch;           ///< the patch's pose in submap s (a trajectory pose)
  std::int64_t patch_stamp_ns = 0;
  tessera::Pose2 match;                                  ///< the patch's pose in submap t
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  ///< of `match` (fine matcher)
  double score = 0.0;
  bool global = false;  ///< found by the global search (else near a prediction)
};

/// Stamped pose of the robot in a submap's frame (Submap.trajectory).
struct SubmapTrajectoryPose {
  std::int64_t stamp_ns = 0;
  tessera::Pose2 pose;
};

struct MapMergerCounts {
  std::uint64_t submaps = 0, submaps_rejected = 0, patches = 0, patches_sparse = 0;
  std::uint64_t global_searches = 0, global_coarse_rejected = 0, global_ambiguous = 0;
  std::uint64_t refined_rejected = 0, conflicting = 0, candidates = 0, disagreeing = 0;
  std::uint64_t joined_searches = 0, joined_rejected = 0, closures = 0, joins = 0;
  double match_seconds = 0.0;
};

class MapMerger {
 public:
  /// `robots` >= 2. Throws std::invalid_argument naming a bad option.
  MapMerger(int robots, MapMergerOptions options = {});
  ~MapMerger();
  MapMerger(MapMerger&&) noexcept;
  MapMerger& operator=(MapMerger&&) noexcept;

  /// A finished submap of `robot`: cells in its own frame, origin `pose` in the robot's frame,
  /// the robot's poses in it. Searches its patches against the other robots' submaps. Returns
  /// "" or why it was left out (bad robot, grid or pose; a repeated id is ignored).
  std::string addSubmap(int robot, int id, tessera::grid::OccupancyMap grid,
                        const tessera::Pose2& pose,
                        const std::vector<SubmapTrajectoryPose>& trajectory);
  /// The robot's optimiser moved submap `id` (ignored when unknown or non-finite).
  void setPose(int robot, int id, const tessera::Pose2& pose);

  int robots() const { return robots_; }
  /// Pose of `robot`'s frame in the merged frame (robot 0's), when joined to robot 0.
  std::optional<tessera::Pose2> frame(int robot) const;
  /// Pose of robot b's frame in robot a's when the two are joined (through any robots).
  std::optional<tessera::Pose2> relativeFrame(int a, int b) const;
  /// Every accepted inter-robot closure, in the order found.
  const std::vector<InterRobotClosure>& closures() const { return closures_; }
  /// The frame estimate one closure gives: pose of robot_b's frame in robot_a's, from the
  /// current submap poses.
  tessera::Pose2 estimate(const InterRobotClosure& c) const;
  const MapMergerCounts& counts() const { return counts_; }
  /// The refinement verifier's decisions (global and joined searches together).
  const tessera::scan_matching::LoopVerifierCounts& verifierCounts() const;
  /// Submap `id` of `robot`'s origin in its robot's frame (its latest pose), if known.
  std::optional<tessera::Pose2> submapPose(int robot, int id) const;

  /// The merged map at the submaps' finest resolution: every submap of the robots joined to
  /// robot 0, at frame ⊕ pose. Empty when no submap is placed.
  tessera::grid::OccupancyMap assemble();
  /// Bytes held: packed cells and pyramids.
  std::size_t bytes() const;

 private:
  struct Impl;
  int robots_;
  std::unique_ptr<Impl> impl_;
  std::vector<InterRobotClosure> closures_;
  MapMergerCounts counts_;
};

}  // namespace tessera::laser_slam
