// Synthetic RGB-D input for the mapping3d tests: a small pinhole camera and a fronto-parallel
// wall as a depth image.
#pragma once

#include <tessera/visual_slam/camera.hpp>

#include <cmath>

namespace tessera::test::mapping3d {

/// 64 x 48 pixels, 50 px focal length: small enough for fast octree tests.
inline visual_slam::PinholeCamera smallCamera() {
  visual_slam::PinholeCamera c;
  c.fx = c.fy = 50;
  c.cx = 32;
  c.cy = 24;
  c.width = 64;
  c.height = 48;
  return c;
}

/// Every pixel sees a wall at depth `z` [m] (millimetre units, no colour).
inline visual_slam::RgbdFrame wallFrame(const visual_slam::PinholeCamera& camera, double z) {
  visual_slam::RgbdFrame f;
  f.depth_scale = 1000;
  f.depth =
      cv::Mat(camera.height, camera.width, CV_16UC1, cv::Scalar(std::round(z * f.depth_scale)));
  return f;
}

}  // namespace tessera::test::mapping3d
