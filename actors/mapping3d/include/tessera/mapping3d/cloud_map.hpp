// CloudMap: the point-cloud map of an RGB-D SLAM run. Each keyframe's cloud is stored once, in
// its camera frame, beside the keyframe's current camera-to-world pose; moving a keyframe (after a
// pose-graph optimisation) only replaces its pose. The global cloud is assembled on demand: every
// keyframe's cloud at its pose, voxel-filtered with one leaf, and written as binary PCD or PLY
// (pcl::io) for CloudCompare / pcl_viewer. Not thread-safe: one owner (the map actor) calls it.
#pragma once

#include <tessera/mapping3d/keyframe_cloud.hpp>

#include <Eigen/Geometry>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <utility>
#include <vector>

namespace tessera::mapping3d {

struct CloudMapOptions {
  double voxel_leaf = 0.02;  ///< [m] leaf of the assembled global cloud; 0 = no filter

  template <class V>
  void visit(V& v) {
    v("voxel_leaf", voxel_leaf, "voxel-grid leaf of the assembled global cloud; 0 = none [m]");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

/// One keyframe as the map keeps it: its cloud (camera frame, shared, never modified) and pose.
struct PlacedCloud {
  std::shared_ptr<const PointCloud> cloud;
  Eigen::Isometry3d camera_to_world = Eigen::Isometry3d::Identity();
};

class CloudMap {
 public:
  /// Throws std::invalid_argument for bad options.
  explicit CloudMap(const CloudMapOptions& options = {});

  /// Adds (or replaces) keyframe `id`. Throws std::invalid_argument naming "pose" when the pose
  /// is not finite or its rotation not orthonormal, "cloud" when colours and points differ in
  /// count.
  void setKeyframe(std::uint64_t id, PointCloud cloud, const Eigen::Isometry3d& camera_to_world);
  /// Moves keyframe `id`. Throws std::out_of_range for an unknown id, std::invalid_argument for a
  /// bad pose (as setKeyframe).
  void setPose(std::uint64_t id, const Eigen::Isometry3d& camera_to_world);

  /// Drops keyframe `id` and its cloud (lifelong mode: the graph trimmed it); false when unknown.
  bool removeKeyframe(std::uint64_t id) { return keyframes_.erase(id) != 0; }

  bool contains(std::uint64_t id) const { return keyframes_.count(id) != 0; }
  std::size_t keyframeCount() const { return keyframes_.size(); }
  /// The keyframes' ids, ascending.
  std::vector<std::uint64_t> ids() const;
  /// Points over all keyframes' clouds, before the global filter.
  std::size_t pointCount() const;
  /// Throws std::out_of_range for an unknown id.
  const PlacedCloud& keyframe(std::uint64_t id) const;
  /// Every keyframe (id order): what an OctoMap rebuild takes as its snapshot.
  std::vector<PlacedCloud> snapshot() const;

  /// Every keyframe's cloud at its pose, in the world frame, voxel-filtered at options.voxel_leaf.
  PointCloud assemble() const;

  /// Writes assemble() as binary PCD / binary little-endian PLY (points x y z, with rgb when the
  /// clouds have colour). Throws std::runtime_error naming the file when the map is empty (PCL
  /// writes no empty cloud) or writing fails.
  void writePcd(const std::filesystem::path& file) const;
  void writePly(const std::filesystem::path& file) const;

  const CloudMapOptions& options() const { return options_; }

 private:
  CloudMapOptions options_;
  std::map<std::uint64_t, PlacedCloud> keyframes_;
};

/// Throws std::invalid_argument naming `field` when `pose` has a non-finite entry or a rotation
/// that is not orthonormal (within 1e-3).
void checkPose(const Eigen::Isometry3d& pose, const char* field);

/// Writes `cloud` (binary PCD) / reads a PCD or PLY file back (tests, tools). Throw
/// std::runtime_error naming the file.
void writePcd(const PointCloud& cloud, const std::filesystem::path& file);
void writePly(const PointCloud& cloud, const std::filesystem::path& file);
PointCloud readPcd(const std::filesystem::path& file);
PointCloud readPly(const std::filesystem::path& file);

}  // namespace tessera::mapping3d
