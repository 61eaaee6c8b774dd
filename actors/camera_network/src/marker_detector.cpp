// ArUco marker detection: see marker_detector.hpp.
#include <tessera/camera_network/marker_detector.hpp>

#include <opencv2/aruco.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace tessera::camera_network {

namespace marker_detector_detail {

struct NamedDictionary {
  const char* name;
  cv::aruco::PREDEFINED_DICTIONARY_NAME id;
};

constexpr NamedDictionary kDictionaries[] = {
    {"4x4_50", cv::aruco::DICT_4X4_50},
    {"4x4_100", cv::aruco::DICT_4X4_100},
    {"4x4_250", cv::aruco::DICT_4X4_250},
    {"4x4_1000", cv::aruco::DICT_4X4_1000},
    {"5x5_50", cv::aruco::DICT_5X5_50},
    {"5x5_100", cv::aruco::DICT_5X5_100},
    {"5x5_250", cv::aruco::DICT_5X5_250},
    {"5x5_1000", cv::aruco::DICT_5X5_1000},
    {"6x6_50", cv::aruco::DICT_6X6_50},
    {"6x6_100", cv::aruco::DICT_6X6_100},
    {"6x6_250", cv::aruco::DICT_6X6_250},
    {"6x6_1000", cv::aruco::DICT_6X6_1000},
    {"7x7_50", cv::aruco::DICT_7X7_50},
    {"7x7_100", cv::aruco::DICT_7X7_100},
    {"7x7_250", cv::aruco::DICT_7X7_250},
    {"7x7_1000", cv::aruco::DICT_7X7_1000},
    {"aruco_original", cv::aruco::DICT_ARUCO_ORIGINAL},
};

cv::Ptr<cv::aruco::Dictionary> dictionaryNamed(const std::string& name) {
  for (const auto& d : kDictionaries)
    if (name == d.name) return cv::aruco::getPredefinedDictionary(d.id);
  std::string known;
  for (const auto& d : kDictionaries) known += std::string(known.empty() ? "" : ", ") + d.name;
  throw std::invalid_argument("marker detector: dictionary must be one of " + known + ", got \"" +
                              name + "\"");
}

void require(bool ok, const char* key, const std::string& rule) {
  if (!ok) throw std::invalid_argument(std::string("marker detector: ") + key + " " + rule);
}

/// The image as grey (CV_8UC1): a view of it, or its conversion.
cv::Mat greyOf(const cv::Mat& image) {
  if (image.empty()) throw std::invalid_argument("marker detector: the image is empty");
  if (image.type() == CV_8UC1) return image;
  if (image.type() != CV_8UC3)
    throw std::invalid_argument("marker detector: the image must be CV_8UC1 or CV_8UC3, got " +
                                cv::typeToString(image.type()));
  cv::Mat grey;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  return grey;
}

/// Mean edge length of the marker's quadrilateral [px].
double sideOf(const std::array<Eigen::Vector2d, 4>& c) {
  double sum = 0;
  for (std::size_t k = 0; k < 4; ++k) sum += (c[(k + 1) % 4] - c[k]).norm();
  return 0.25 * sum;
}

/// Intersection of the diagonals 0-2 and 1-3; the corners' mean when they are (nearly) parallel.
Eigen::Vector2d diagonalIntersection(const std::array<Eigen::Vector2d, 4>& c) {
  const Eigen::Vector2d d1 = c[2] - c[0], d2 = c[3] - c[1];
  const double cross = d1.x() * d2.y() - d1.y() * d2.x();
  if (std::abs(cross) <= 1e-12 * d1.squaredNorm() * d2.squaredNorm() || !std::isfinite(cross))
    return 0.25 * (c[0] + c[1] + c[2] + c[3]);
  // c0 + t d1 = c1 + s d2  ->  t = ((c1 - c0) x d2) / (d1 x d2)
  const Eigen::Vector2d e = c[1] - c[0];
  const double t = (e.x() * d2.y() - e.y() * d2.x()) / cross;
  return c[0] + t * d1;
}

}  // namespace marker_detector_detail

struct MarkerDetector::Impl {
  cv::Ptr<cv::aruco::Dictionary> dictionary;
  cv::Ptr<cv::aruco::DetectorParameters> parameters;
};

MarkerDetector::MarkerDetector(const MarkerDetectorOptions& options) : options_(options) {
  namespace d = marker_detector_detail;
  auto impl = std::make_shared<Impl>();
  impl->dictionary = d::dictionaryNamed(options.dictionary);
  d::require(options.threshold_window_min_px >= 3, "threshold_window_min_px", "must be >= 3");
  d::require(options.threshold_window_max_px >= options.threshold_window_min_px,
             "threshold_window_max_px", "must be >= threshold_window_min_px");
  d::require(options.threshold_window_step_px >= 1, "threshold_window_step_px", "must be >= 1");
  d::require(std::isfinite(options.track_margin) && options.track_margin >= 0, "track_margin",
             "must be finite and >= 0");
  impl->parameters = cv::aruco::DetectorParameters::create();
  // One window of about two cells (7 px) thresholds the robot's marker as well as OpenCV's
  // default three (3, 13, 23 px) at a seventh of the cost (`tessera bench marker_detection
  // --window-min 3 --window-max 23` measures the default).
  impl->parameters->adaptiveThreshWinSizeMin = options.threshold_window_min_px;
  impl->parameters->adaptiveThreshWinSizeMax = options.threshold_window_max_px;
  impl->parameters->adaptiveThreshWinSizeStep = options.threshold_window_step_px;
  // A ceiling camera sees the robot's marker with cells of 3 to 4 px: read each bit from the
  // middle of its cell (the default margin of 0.13 lets the blurred border leak in and misses
  // about 3 % of such markers).
  impl->parameters->perspectiveRemoveIgnoredMarginPerCell = 0.3;
  if (options.refine_corners) {
    impl->parameters->cornerRefinementMethod = cv::aruco::CORNER_REFINE_SUBPIX;
    // Small markers seen from the ceiling have cells of a few pixels: a small window (5 x 5 px)
    // keeps the refinement on the marker's own corner; larger ones reach the inner bits.
    impl->parameters->cornerRefinementWinSize = 2;
  }
  impl_ = std::move(impl);
}

std::vector<DetectedMarker> MarkerDetector::detect(const cv::Mat& image) const {
  return detect(image, cv::Rect(0, 0, image.cols, image.rows));
}

std::vector<DetectedMarker> MarkerDetector::detect(const cv::Mat& image,
                                                   const cv::Rect& window) const {
  if (image.empty()) throw std::invalid_argument("marker detector: the image is empty");
  const cv::Rect roi = window & cv::Rect(0, 0, image.cols, image.rows);
  // Checks the type even for an empty window.
  const cv::Mat grey =
      marker_detector_detail::greyOf(roi.empty() ? image(cv::Rect(0, 0, 1, 1)) : image(roi));
  if (roi.empty()) return {};

  // OpenCV's perimeter limits are rates of the searched image's larger side: a window keeps the
  // whole image's limits in pixels.
  cv::Ptr<cv::aruco::DetectorParameters> parameters = impl_->parameters;
  const int side = std::max(roi.width, roi.height), full = std::max(image.cols, image.rows);
  if (side != full) {
    parameters = cv::makePtr<cv::aruco::DetectorParameters>(*impl_->parameters);
    const double scale = static_cast<double>(full) / side;
    parameters->minMarkerPerimeterRate *= scale;
    parameters->maxMarkerPerimeterRate *= scale;
  }
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  cv::aruco::detectMarkers(grey, impl_->dictionary, corners, ids, parameters);

  std::vector<DetectedMarker> out;
  out.reserve(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (corners[i].size() != 4) continue;
    DetectedMarker m;
    m.id = ids[i];
    for (std::size_t k = 0; k < 4; ++k)
      m.corners[k] = {corners[i][k].x + roi.x, corners[i][k].y + roi.y};
    m.centre = marker_detector_detail::diagonalIntersection(m.corners);
    out.push_back(m);
  }
  std::sort(out.begin(), out.end(), [](const DetectedMarker& a, const DetectedMarker& b) {
    return a.id != b.id ? a.id < b.id : a.centre.x() < b.centre.x();
  });
  return out;
}

MarkerTracker::MarkerTracker(MarkerDetector detector, int marker_id)
    : detector_(std::move(detector)), marker_id_(marker_id) {}

std::vector<DetectedMarker> MarkerTracker::detect(const cv::Mat& image) {
  const auto find = [this](const std::vector<DetectedMarker>& markers) {
    return std::find_if(markers.begin(), markers.end(),
                        [this](const DetectedMarker& m) { return m.id == marker_id_; });
  };
  window_ = {};
  from_window_ = false;
  const double margin_sides = detector_.options().track_margin;
  if (last_ && margin_sides > 0) {
    const auto& c = last_->corners;
    double u0 = c[0].x(), u1 = u0, v0 = c[0].y(), v1 = v0;
    for (const Eigen::Vector2d& p : c) {
      u0 = std::min(u0, p.x());
      u1 = std::max(u1, p.x());
      v0 = std::min(v0, p.y());
      v1 = std::max(v1, p.y());
    }
    const double margin = margin_sides * marker_detector_detail::sideOf(c);
    // The pixels x0..x1, y0..y1 (inclusive), clipped to the image.
    const int x0 = static_cast<int>(std::floor(u0 - margin)),
              y0 = static_cast<int>(std::floor(v0 - margin));
    const int x1 = static_cast<int>(std::ceil(u1 + margin)),
              y1 = static_cast<int>(std::ceil(v1 + margin));
    window_ = cv::Rect(x0, y0, x1 - x0 + 1, y1 - y0 + 1) & cv::Rect(0, 0, image.cols, image.rows);
    if (!window_.empty()) {
      auto markers = detector_.detect(image, window_);
      if (const auto it = find(markers); it != markers.end()) {
        last_ = *it;
        from_window_ = true;
        return markers;
      }
    }
  }
  auto markers = detector_.detect(image);
  const auto it = find(markers);
  last_ = it != markers.end() ? std::optional<DetectedMarker>(*it) : std::nullopt;
  return markers;
}

}  // namespace tessera::camera_network
