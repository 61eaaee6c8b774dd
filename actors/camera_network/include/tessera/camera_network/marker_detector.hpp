// ArUco marker detection in an environment camera's image: the marker on the robot, as pixels.
//
// Input: a CV_8UC1 (grey) or CV_8UC3 (BGR, converted to grey) image. Output: every marker of the
// configured dictionary found in it, with its id (markers other than the robot's are reported too,
// so the caller can count and ignore them), its four corners in ArUco's order (the marker image's
// top-left, top-right, bottom-right, bottom-left; clockwise in the image for an unmirrored view)
// and its centre, the intersection of the diagonals (the projection of the square's centre under
// any homography, unlike the corners' mean). Pixels in OpenCV's convention: (u, v) = (column,
// row), integer values at pixel centres. Results are sorted by id, then by centre u.
//
// OpenCV's ArUco module stays in the .cpp file. A detector is immutable once built: detect() is
// const and may be called from several threads; copies share the dictionary.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <array>
#include <memory>
#include <string>
#include <vector>

namespace tessera::camera_network {

struct MarkerDetectorOptions {
  /// Predefined ArUco dictionary: "4x4_50", "4x4_100", "4x4_250", "4x4_1000", the same for 5x5,
  /// 6x6 and 7x7, or "aruco_original".
  std::string dictionary = "4x4_50";
  bool refine_corners = true;  ///< sub-pixel corner refinement

  template <class V>
  void visit(V& v) {
    v("dictionary", dictionary,
      "ArUco dictionary: 4x4_50, 4x4_100, 4x4_250, 4x4_1000, likewise 5x5_*, 6x6_*, 7x7_*, or "
      "aruco_original");
    v("refine_corners", refine_corners, "refine the marker corners to sub-pixel accuracy");
  }
};

/// One marker found in an image.
struct DetectedMarker {
  int id = 0;
  std::array<Eigen::Vector2d, 4> corners;  ///< [px] top-left, top-right, bottom-right, bottom-left
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();  ///< [px] intersection of the diagonals
};

class MarkerDetector {
 public:
  /// Throws std::invalid_argument naming the bad option (an unknown dictionary).
  explicit MarkerDetector(const MarkerDetectorOptions& options = {});

  /// The markers in `image` (CV_8UC1 or CV_8UC3). Throws std::invalid_argument for an empty image
  /// or another type.
  std::vector<DetectedMarker> detect(const cv::Mat& image) const;

  const MarkerDetectorOptions& options() const { return options_; }

 private:
  struct Impl;
  MarkerDetectorOptions options_;
  std::shared_ptr<const Impl> impl_;
};

}  // namespace tessera::camera_network
