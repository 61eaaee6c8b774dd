// FeatureExtractor: keypoints spread over the image, their descriptors, and their 3D points from
// the depth image (docs/algorithms.md#rgb-d-visual-odometry).
//
// The image is split into grid_cols x grid_rows cells. Each cell runs its own detector (ORB or
// SIFT from OpenCV) on the cell plus a margin, in parallel over cells (TBB), and keeps its
// strongest keypoints up to an even share of max_features. ORB detects level by level on one
// shared image pyramid (the cell's share split over the levels by their area, as ORB splits its
// own budget), and a level of a cell short of half its quota retries with min_fast_threshold, so
// weakly textured cells still contribute. Descriptors are then computed once on the whole image,
// which may drop a few keypoints at the image border.
//
// Depth: the reading under each keypoint (rounded pixel) gives z = d / depth_scale and the point
// x = (u - cx) z / fx, y = (v - cy) z / fy, z in the camera's optical frame [m]. A keypoint has no
// 3D point when the reading is 0, outside [min_depth, max_depth], or when it sits on a depth
// edge: within depth_window pixels, fewer than half the readings are valid or they spread over
// more than depth_edge_abs + depth_edge_rel * z (foreground and background mixed).
//
// Thread-safe for concurrent extract() calls (no mutable state).
#pragma once

#include <tessera/visual_slam/camera.hpp>

#include <opencv2/core.hpp>

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace tessera::visual_slam {

enum class FeatureType { kOrb, kSift };
constexpr std::array<std::pair<const char*, FeatureType>, 2> optionNames(FeatureType) {
  return {{{"orb", FeatureType::kOrb}, {"sift", FeatureType::kSift}}};
}

struct FeatureExtractorOptions {
  FeatureType type = FeatureType::kOrb;
  int max_features = 1000;  ///< over the whole image; each cell keeps max_features / cells
  int grid_cols = 8;
  int grid_rows = 6;
  int orb_levels = 4;             ///< pyramid levels per cell
  double orb_scale_factor = 1.2;  ///< between pyramid levels
  int fast_threshold = 20;        ///< ORB's FAST threshold [grey levels]
  int min_fast_threshold = 7;     ///< retry threshold for a cell short of keypoints
  double sift_contrast_threshold = 0.04;
  double min_depth = 0.3;        ///< [m] nearer readings are invalid (Kinect minimum range)
  double max_depth = 6.0;        ///< [m] farther readings are invalid (noise grows with z²)
  int depth_window = 2;          ///< [px] half-size of the neighbourhood checked for depth edges
  double depth_edge_abs = 0.03;  ///< [m] largest depth spread in the neighbourhood ...
  double depth_edge_rel = 0.03;  ///< ... plus this fraction of z

  template <class V>
  void visit(V& v) {
    v("feature_type", type, "keypoint detector and descriptor");
    v("max_features", max_features, "keypoints per frame, shared evenly by the grid cells");
    v("grid_cols", grid_cols, "grid cells across the image");
    v("grid_rows", grid_rows, "grid cells down the image");
    v("orb_levels", orb_levels, "ORB pyramid levels");
    v("orb_scale_factor", orb_scale_factor, "ORB scale between pyramid levels");
    v("fast_threshold", fast_threshold, "ORB FAST threshold [grey levels]");
    v("min_fast_threshold", min_fast_threshold,
      "FAST threshold of the retry in a cell short of keypoints [grey levels]");
    v("sift_contrast_threshold", sift_contrast_threshold, "SIFT contrast threshold");
    v("min_depth", min_depth, "nearest valid depth [m]");
    v("max_depth", max_depth, "farthest valid depth [m]");
    v("depth_window", depth_window, "half-size of the depth-edge neighbourhood [px]");
    v("depth_edge_abs", depth_edge_abs, "largest depth spread around a keypoint [m] ...");
    v("depth_edge_rel", depth_edge_rel, "... plus this fraction of its depth");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

/// Why keypoints got no 3D point.
struct DepthRejects {
  std::size_t missing = 0;       ///< no reading under the keypoint
  std::size_t out_of_range = 0;  ///< outside [min_depth, max_depth]
  std::size_t edge = 0;          ///< neighbourhood sparse or inconsistent
};

/// One frame's features. Index i refers to the same feature in every vector and descriptor row.
struct Features {
  std::vector<cv::KeyPoint> keypoints;  ///< pixel coordinates in the full image
  cv::Mat descriptors;  ///< one row per keypoint: CV_8U, 32 bytes (ORB) or CV_32F, 128 (SIFT)
  std::vector<Eigen::Vector3d> points;  ///< camera frame [m]; meaningful where has_depth[i]
  std::vector<std::uint8_t> has_depth;
  std::size_t with_depth = 0;
  std::vector<int> per_cell;  ///< keypoints kept per grid cell, row-major (before descriptors)
  int cell_budget = 0;        ///< the most a cell may keep
  DepthRejects rejects;

  std::size_t size() const { return keypoints.size(); }
};

class FeatureExtractor {
 public:
  /// Throws std::invalid_argument for bad options or intrinsics.
  FeatureExtractor(const FeatureExtractorOptions& options, const PinholeCamera& camera);

  /// Features of a grey image (CV_8UC1, the camera's size). `depth` is CV_16UC1 of the same size
  /// or empty (no 3D points). Throws std::invalid_argument for a wrong type or size.
  Features extract(const cv::Mat& gray, const cv::Mat& depth, double depth_scale) const;

  const FeatureExtractorOptions& options() const { return options_; }
  const PinholeCamera& camera() const { return camera_; }

 private:
  FeatureExtractorOptions options_;
  PinholeCamera camera_;
};

}  // namespace tessera::visual_slam
