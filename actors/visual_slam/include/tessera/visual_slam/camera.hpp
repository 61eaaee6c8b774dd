// The pinhole camera of an RGB-D frame and the frame itself as the visual front end takes it.
//
// Frames: the camera is in the optical convention (x right, y down, z forward); a pixel (u, v)
// with depth z back-projects to x = (u - cx) z / fx, y = (v - cy) z / fy. Units: pixels, metres.
// The intrinsics are those of the image the depth is given in; the colour image is assumed to be
// registered to it (for 7-Scenes, whose colour is not, see
// docs/algorithms.md#rgb-d-visual-odometry).
#pragma once

#include <opencv2/core.hpp>

#include <Eigen/Core>

namespace tessera::visual_slam {

struct PinholeCamera {
  double fx = 0, fy = 0, cx = 0, cy = 0;  ///< [px]
  int width = 0, height = 0;              ///< [px]

  /// Throws std::invalid_argument naming the first bad field (non-finite or non-positive focal
  /// length, non-finite principal point, non-positive size).
  void validate() const;

  Eigen::Vector3d backProject(double u, double v, double z) const {
    return {(u - cx) * z / fx, (v - cy) * z / fy, z};
  }
  Eigen::Vector2d project(const Eigen::Vector3d& p) const {
    return {fx * p.x() / p.z() + cx, fy * p.y() / p.z() + cy};
  }
  bool inside(const Eigen::Vector2d& uv) const {
    return uv.x() >= 0 && uv.y() >= 0 && uv.x() < width && uv.y() < height;
  }
};

/// One RGB-D frame. `image`: CV_8UC1 grey or CV_8UC3 in R, G, B order (as the dataset readers
/// decode it); `depth`: CV_16UC1, 0 = no reading, metres = value / depth_scale. The Mats may
/// wrap caller-owned buffers: nothing keeps them after the call that receives the frame.
struct RgbdFrame {
  cv::Mat image;
  cv::Mat depth;
  double depth_scale = 1000;  ///< depth units per metre
  double timestamp = 0;       ///< [s]
};

}  // namespace tessera::visual_slam
