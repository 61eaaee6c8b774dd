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
// Speed: a ceiling camera sees the robot's marker with cells of 3 to 4 px, and one adaptive
// threshold window of about two cells (7 px) finds it as well as OpenCV's default three (3, 13
// and 23 px) at a seventh of the cost: ~0.5 ms instead of ~3.5 ms per 640 x 480 frame (`tessera
// bench marker_detection`, docs/benchmarks.md). A MarkerTracker following the marker through a
// camera's frames searches a window around its last detection first: ~0.04 ms.
//
// OpenCV's ArUco module stays in the .cpp file. A detector is immutable once built: detect() is
// const and may be called from several threads; copies share the dictionary.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::camera_network {

struct MarkerDetectorOptions {
  /// Predefined ArUco dictionary: "4x4_50", "4x4_100", "4x4_250", "4x4_1000", the same for 5x5,
  /// 6x6 and 7x7, or "aruco_original".
  std::string dictionary = "4x4_50";
  bool refine_corners = true;  ///< sub-pixel corner refinement
  /// Adaptive threshold window sizes [px] tried, min to max in steps (OpenCV's
  /// adaptiveThreshWinSize*); each one costs a pass over the image. About two marker cells.
  int threshold_window_min_px = 7;
  int threshold_window_max_px = 7;
  int threshold_window_step_px = 10;
  /// MarkerTracker: the window around the last detection reaches this many marker sides past the
  /// marker on every side; 0 searches the whole image every frame.
  double track_margin = 1.0;

  template <class V>
  void visit(V& v) {
    v("dictionary", dictionary,
      "ArUco dictionary: 4x4_50, 4x4_100, 4x4_250, 4x4_1000, likewise 5x5_*, 6x6_*, 7x7_*, or "
      "aruco_original");
    v("refine_corners", refine_corners, "refine the marker corners to sub-pixel accuracy");
    v("threshold_window_min_px", threshold_window_min_px,
      "smallest adaptive threshold window [px] (about two marker cells), >= 3");
    v("threshold_window_max_px", threshold_window_max_px,
      "largest adaptive threshold window [px]; each window tried costs a pass over the image");
    v("threshold_window_step_px", threshold_window_step_px,
      "step between the threshold windows tried [px], >= 1");
    v("track_margin", track_margin,
      "a tracked marker is searched first within this many marker sides of its last detection; "
      "0 = always the whole image");
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
  /// Throws std::invalid_argument naming the bad option (an unknown dictionary, threshold windows
  /// below 3 px or min > max, a step below 1, a negative or non-finite track_margin).
  explicit MarkerDetector(const MarkerDetectorOptions& options = {});

  /// The markers in `image` (CV_8UC1 or CV_8UC3). Throws std::invalid_argument for an empty image
  /// or another type.
  std::vector<DetectedMarker> detect(const cv::Mat& image) const;
  /// The markers inside `window` of `image` (clipped to the image; none for an empty window), in
  /// the whole image's pixels. The marker size limits are those of the whole image.
  std::vector<DetectedMarker> detect(const cv::Mat& image, const cv::Rect& window) const;

  const MarkerDetectorOptions& options() const { return options_; }

 private:
  struct Impl;
  MarkerDetectorOptions options_;
  std::shared_ptr<const Impl> impl_;
};

/// Follows one marker (id `marker_id`) through the frames of one camera. Each frame is searched
/// first in a window around the marker's last detection: its corners' bounding box grown by
/// options().track_margin marker sides (mean edge length) on every side, clipped to the image.
/// When the window does not hold the marker, or there is no last detection, the whole image is
/// searched. The result is detect()'s; when the window answered it holds only the markers inside
/// the window. Not thread-safe (one tracker per camera); copies are independent.
class MarkerTracker {
 public:
  MarkerTracker(MarkerDetector detector, int marker_id);

  /// The markers in `image`, as MarkerDetector::detect (same exceptions).
  std::vector<DetectedMarker> detect(const cv::Mat& image);
  /// Forgets the last detection: the next frame is searched whole.
  void reset() { last_.reset(); }

  /// The last detection of the marker, if the last frame had it.
  const std::optional<DetectedMarker>& last() const { return last_; }
  /// The window the last detect() searched first (empty when there was none).
  const cv::Rect& lastWindow() const { return window_; }
  /// Whether the last detect() found the marker in its window, without the whole image.
  bool answeredFromWindow() const { return from_window_; }
  const MarkerDetector& detector() const { return detector_; }

 private:
  MarkerDetector detector_;
  int marker_id_;
  std::optional<DetectedMarker> last_;
  cv::Rect window_;
  bool from_window_ = false;
};

}  // namespace tessera::camera_network
