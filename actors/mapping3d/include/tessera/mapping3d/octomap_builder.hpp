// OctoMapBuilder: an OctoMap (octomap::OcTree) of the keyframes' clouds, with the log-odds update
//   L(n | z_1:t) = clamp(L(n | z_1:t-1) + l_z, l_min, l_max),
// l_z = l_hit for the voxel a point falls in and l_miss for the voxels its ray from the sensor
// crosses (docs/algorithms.md#rgb-d-maps). Each voxel is updated at most once per inserted cloud.
//
// Rebuild: after a loop closure moves keyframes, rebuild(snapshot) re-inserts every keyframe at
// its new pose into a fresh tree in the background; until it is done every query and write sees
// the old tree (it keeps receiving insert()s), then the new tree replaces it in one swap, the
// clouds inserted meanwhile applied to it first. A request made while a rebuild runs waits for it
// and replaces any request still waiting, so during a run of frequent loop closures the map
// follows one rebuild behind; waitForRebuild() abandons a running rebuild that a waiting request
// has made stale. The rebuild ray-casts clouds on rebuild_threads threads (every core for one that
// waitForRebuild waits for) and applies them to the tree in keyframe order: the tree is the one
// inserting them one by one gives.
//
// Preview: occupiedVoxels(max_points) gives the centres of the served tree's occupied voxels, at
// the leaf resolution or, when there are more than max_points of them, at the finest coarser
// depth (voxel edge 2x, 4x, ...) where they fit: a coarse voxel is occupied when any leaf below it
// is (octomap's inner nodes hold their children's maximum log-odds, brought up to date first).
//
// Thread-safe: insert/queries/writes from one or more threads, the rebuild on its own thread.
// octomap types stay in the .cpp: the tree is reached through this class only.
#pragma once

#include <tessera/mapping3d/cloud_map.hpp>
#include <tessera/mapping3d/keyframe_cloud.hpp>

#include <Eigen/Geometry>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string_view>
#include <utility>
#include <vector>

namespace tessera::mapping3d {

/// How a cloud goes into the tree (all three are octomap's own):
///  * kPointCloud: insertPointCloud, each point's ray traced (computeUpdate);
///  * kDiscretized: insertPointCloud with discretize = true: points first merged per voxel, one ray
///    per occupied voxel (fewer rays when many points share a voxel);
///  * kRays: insertPointCloudRays, every ray updated in turn (a voxel may be updated more than once
///    per cloud; octomap parallelises it only when built with OpenMP).
enum class InsertMethod { kPointCloud, kDiscretized, kRays };
constexpr std::array<std::pair<const char*, InsertMethod>, 3> optionNames(InsertMethod) {
  return {{{"pointcloud", InsertMethod::kPointCloud},
           {"discretized", InsertMethod::kDiscretized},
           {"rays", InsertMethod::kRays}}};
}
std::string_view methodName(InsertMethod m);

struct OctoMapOptions {
  double resolution = 0.05;  ///< [m] leaf voxel edge
  double max_range = 4.0;    ///< [m] points farther from the sensor are cut to this; <= 0 = none
  /// Log-odds increments and clamping (octomap's defaults: p = 0.7 / 0.4, clamp p 0.1192 / 0.971).
  double log_odds_hit = 0.85;
  double log_odds_miss = -0.405;
  double log_odds_min = -2.0;
  double log_odds_max = 3.5;
  double log_odds_occupied = 0.0;  ///< a voxel with L above this is occupied (p = 0.5)
  InsertMethod method = InsertMethod::kDiscretized;
  /// [m] voxel-filter each cloud at this leaf before insertion (0 = off); at the resolution it
  /// keeps one point per voxel, which is what the tree can hold anyway.
  double downsample_leaf = 0.0;
  /// octomap's lazy evaluation: inner nodes are updated and the tree pruned
  /// (updateInnerOccupancy, prune) every `prune_period` clouds instead of after every voxel
  /// update: the same leaves, faster (docs/benchmarks.md#octomap-insertion-tessera-bench-octomap).
  bool lazy_eval = true;
  /// With lazy_eval: clouds between two updates of the inner nodes, and before any statistics or
  /// write. Both walk the whole tree, so doing them after every cloud made a long run quadratic
  /// (docs/algorithms.md#rgb-d-maps); leaf queries are exact in between.
  int prune_period = 20;
  /// Threads that ray-cast clouds in a background rebuild (0 = every core); the default leaves
  /// the other cores to tracking. A rebuild started while waitForRebuild waits uses every core.
  /// The tree itself is updated by one thread, in keyframe order.
  int rebuild_threads = 1;

  template <class V>
  void visit(V& v) {
    v("resolution", resolution, "leaf voxel edge [m]");
    v("max_range", max_range, "points farther from the sensor are cut to this; <= 0 = none [m]");
    v("log_odds_hit", log_odds_hit, "log-odds added to the voxel a point falls in");
    v("log_odds_miss", log_odds_miss, "log-odds added to voxels a ray crosses (negative)");
    v("log_odds_min", log_odds_min, "lower clamp of a voxel's log-odds");
    v("log_odds_max", log_odds_max, "upper clamp of a voxel's log-odds");
    v("log_odds_occupied", log_odds_occupied, "log-odds above which a voxel is occupied");
    v("method", method, "insertion: pointcloud, discretized or rays");
    v("downsample_leaf", downsample_leaf, "voxel-filter clouds before insertion; 0 = off [m]");
    v("lazy_eval", lazy_eval, "update inner nodes once per prune_period clouds, not per voxel");
    v("prune_period", prune_period,
      "with lazy_eval: clouds between updates of the inner nodes and pruning (1 = every cloud)");
    v("rebuild_threads", rebuild_threads,
      "threads ray-casting clouds in a background rebuild (one waited for uses all); 0 = all");
  }
  /// Throws std::invalid_argument naming the first bad option (l_min < l_occupied < l_max,
  /// l_miss < 0 < l_hit, resolution > 0, all finite).
  void validate() const;
};

enum class Occupancy { kUnknown, kFree, kOccupied };

struct OctoMapStats {
  std::size_t leaves = 0, occupied_leaves = 0, free_leaves = 0;
  std::size_t memory_bytes = 0;     ///< OcTree::memoryUsage()
  std::size_t clouds_inserted = 0;  ///< into the tree being served
  std::size_t points_inserted = 0;  ///< points given to octomap (after any downsampling)
  std::size_t rebuilds_completed = 0;
  std::size_t rebuilds_abandoned = 0;  ///< by waitForRebuild, for a newer request
};

/// A preview of the served tree's occupied space (OctoMapBuilder::occupiedVoxels).
struct OccupiedVoxels {
  std::vector<Eigen::Vector3f> centres;  ///< [m, world frame] one per occupied voxel
  double voxel_size = 0;                 ///< [m] edge of the voxels the centres stand for
  int depth = 0;                         ///< octree depth of those voxels (16 = the leaves)
  std::uint64_t revision = 0;            ///< revision() of the tree they were taken from
};

class OctoMapBuilder {
 public:
  /// Throws std::invalid_argument for bad options.
  explicit OctoMapBuilder(const OctoMapOptions& options = {});
  /// Waits for a running rebuild.
  ~OctoMapBuilder();
  OctoMapBuilder(const OctoMapBuilder&) = delete;
  OctoMapBuilder& operator=(const OctoMapBuilder&) = delete;

  /// Inserts `cloud` (camera frame) seen from `camera_to_world`. Throws std::invalid_argument
  /// naming "pose" for a non-finite or non-rigid pose; non-finite points are skipped.
  void insert(const PointCloud& cloud, const Eigen::Isometry3d& camera_to_world);

  /// Starts re-inserting every keyframe of `keyframes` into a fresh tree in the background (see
  /// the file comment). Throws std::invalid_argument naming "pose" for a bad pose.
  void rebuild(std::vector<PlacedCloud> keyframes);
  bool rebuilding() const;
  /// Blocks until the served tree holds the latest request (a running rebuild that a waiting
  /// request has made stale is abandoned) and no rebuild runs.
  void waitForRebuild();

  /// Occupancy / log-odds of the leaf voxel holding `point` [m, world frame]; log-odds empty when
  /// no measurement reached it.
  Occupancy occupancy(const Eigen::Vector3d& point) const;
  std::optional<double> logOdds(const Eigen::Vector3d& point) const;

  OctoMapStats stats() const;
  /// Centres of the served tree's occupied voxels, at most `max_points` of them: at the leaf
  /// resolution when they fit, else at the finest coarser depth where they do (a pruned leaf
  /// larger than that depth's voxels counts as all the voxels it covers). Empty for an empty map
  /// or max_points = 0. Holds the tree's lock while it walks the tree (inserts wait meanwhile).
  OccupiedVoxels occupiedVoxels(std::size_t max_points) const;
  /// Changes each time the served tree does (an insert, a finished rebuild, readBinary): a map
  /// whose revision is unchanged holds the same voxels.
  std::uint64_t revision() const;
  /// Writes the served tree as an OctoMap binary file (.bt, octovis; free/occupied only). Throws
  /// std::runtime_error naming the file.
  void writeBinary(const std::filesystem::path& file) const;
  /// Replaces the served tree by the one in an OctoMap binary file (after any running rebuild).
  /// Its voxels hold the clamping log-odds (a .bt keeps free/occupied only). Throws
  /// std::runtime_error naming the file when it cannot be read or its resolution is not
  /// options().resolution.
  void readBinary(const std::filesystem::path& file);

  const OctoMapOptions& options() const { return options_; }

 private:
  struct State;
  OctoMapOptions options_;
  std::unique_ptr<State> state_;
};

}  // namespace tessera::mapping3d
