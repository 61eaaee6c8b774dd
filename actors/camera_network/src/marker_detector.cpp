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
  auto impl = std::make_shared<Impl>();
  impl->dictionary = marker_detector_detail::dictionaryNamed(options.dictionary);
  impl->parameters = cv::aruco::DetectorParameters::create();
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
  if (image.empty()) throw std::invalid_argument("marker detector: the image is empty");
  cv::Mat grey;
  if (image.type() == CV_8UC1) {
    grey = image;
  } else if (image.type() == CV_8UC3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else {
    throw std::invalid_argument("marker detector: the image must be CV_8UC1 or CV_8UC3, got " +
                                cv::typeToString(image.type()));
  }
  std::vector<std::vector<cv::Point2f>> corners;
  std::vector<int> ids;
  cv::aruco::detectMarkers(grey, impl_->dictionary, corners, ids, impl_->parameters);

  std::vector<DetectedMarker> out;
  out.reserve(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    if (corners[i].size() != 4) continue;
    DetectedMarker m;
    m.id = ids[i];
    for (std::size_t k = 0; k < 4; ++k) m.corners[k] = {corners[i][k].x, corners[i][k].y};
    m.centre = marker_detector_detail::diagonalIntersection(m.corners);
    out.push_back(m);
  }
  std::sort(out.begin(), out.end(), [](const DetectedMarker& a, const DetectedMarker& b) {
    return a.id != b.id ? a.id < b.id : a.centre.x() < b.centre.x();
  });
  return out;
}

}  // namespace tessera::camera_network
