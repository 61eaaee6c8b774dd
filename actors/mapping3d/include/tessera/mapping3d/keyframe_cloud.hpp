// KeyframeCloud: the points one keyframe's depth image sees, in that keyframe's camera frame
// (optical convention: x right, y down, z forward; metres), voxel-filtered, with colour when the
// frame has one. Kept per keyframe so that a keyframe moved by the pose graph moves its cloud by a
// transform instead of a new back-projection (docs/algorithms.md#rgb-d-maps).
#pragma once

#include <tessera/visual_slam/camera.hpp>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tessera::mapping3d {

/// Points with optional per-point colour (R, G, B). `colors` is empty or the size of `points`.
struct PointCloud {
  std::vector<Eigen::Vector3f> points;              ///< [m]
  std::vector<std::array<std::uint8_t, 3>> colors;  ///< R, G, B; empty = no colour

  std::size_t size() const { return points.size(); }
  bool empty() const { return points.empty(); }
  bool hasColor() const { return !colors.empty(); }
  /// This cloud with every point mapped through `transform` (colours kept).
  PointCloud transformed(const Eigen::Isometry3d& transform) const;
};

struct KeyframeCloudOptions {
  int stride = 2;            ///< every stride-th pixel in u and v (1 = all pixels)
  double min_depth = 0.3;    ///< [m] readings nearer than this are dropped (Kinect: ~0.4 m)
  double max_depth = 4.0;    ///< [m] readings farther than this are dropped (noise grows as z^2)
  double voxel_leaf = 0.01;  ///< [m] voxel-grid leaf of the keyframe's cloud; 0 = no filter

  template <class V>
  void visit(V& v) {
    v("stride", stride, "take every stride-th pixel in u and v");
    v("min_depth", min_depth, "readings nearer than this are dropped [m]");
    v("max_depth", max_depth, "readings farther than this are dropped [m]");
    v("voxel_leaf", voxel_leaf, "voxel-grid leaf of one keyframe's cloud; 0 = none [m]");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

/// The cloud of one RGB-D frame in its camera frame. `frame.depth` must be CV_16UC1 of the
/// camera's size; `frame.image`, when not empty, CV_8UC3 (R, G, B) or CV_8UC1 (grey, stored as
/// R = G = B) of the same size: points then carry its colour. Throws std::invalid_argument naming
/// the field: empty depth, wrong depth type, non-finite or non-positive depth_scale, image or
/// depth size not the camera's, bad intrinsics or options. A frame with no valid reading gives an
/// empty cloud (not an error: the caller counts it).
PointCloud makeKeyframeCloud(const visual_slam::PinholeCamera& camera,
                             const visual_slam::RgbdFrame& frame,
                             const KeyframeCloudOptions& options = {});

/// `cloud` voxel-filtered with pcl::VoxelGrid at `leaf` [m] (one point per occupied voxel: the
/// centroid of its points, colours averaged). leaf <= 0 returns the cloud unchanged. Throws
/// std::invalid_argument for a non-finite leaf.
PointCloud voxelFilter(const PointCloud& cloud, double leaf);

}  // namespace tessera::mapping3d
