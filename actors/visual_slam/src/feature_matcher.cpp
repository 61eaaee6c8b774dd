// FeatureMatcher: brute-force or FLANN kNN with the ratio test and the minimum-distance filter.
#include <tessera/visual_slam/feature_matcher.hpp>

#include <opencv2/core/hal/hal.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/flann.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace tessera::visual_slam {

void FeatureMatcherOptions::validate() const {
  if (!(ratio > 0 && ratio <= 1))
    throw std::invalid_argument("matcher: match_ratio must be in (0, 1]");
  if (!(min_distance_factor >= 0) || !std::isfinite(min_distance_factor))
    throw std::invalid_argument("matcher: min_distance_factor must be >= 0");
  if (!(min_distance_floor >= 0) || !std::isfinite(min_distance_floor))
    throw std::invalid_argument("matcher: min_distance_floor must be >= 0");
  if (algorithm != MatchAlgorithm::kBruteForce && algorithm != MatchAlgorithm::kFlann)
    throw std::invalid_argument("matcher: unknown match_algorithm");
  if (flann_checks < 1) throw std::invalid_argument("matcher: flann_checks must be >= 1");
}

double descriptorDistance(const cv::Mat& a, int i, const cv::Mat& b, int j) {
  if (a.type() == CV_8U)
    return cv::hal::normHamming(a.ptr<std::uint8_t>(i), b.ptr<std::uint8_t>(j), a.cols);
  return std::sqrt(cv::hal::normL2Sqr_(a.ptr<float>(i), b.ptr<float>(j), a.cols));
}

FeatureMatcher::FeatureMatcher(const FeatureMatcherOptions& options) : options_(options) {
  options_.validate();
}

std::vector<cv::DMatch> FeatureMatcher::match(const cv::Mat& query, const cv::Mat& train,
                                              MatchStats* stats) const {
  MatchStats local;
  MatchStats& s = stats != nullptr ? *stats : local;
  s = MatchStats{};
  s.queries = static_cast<std::size_t>(query.rows);
  std::vector<cv::DMatch> out;
  if (query.empty() || train.empty()) return out;
  if (query.type() != train.type() || query.cols != train.cols)
    throw std::invalid_argument("matcher: query and train descriptors differ in type or width");
  if (query.type() != CV_8U && query.type() != CV_32F)
    throw std::invalid_argument("matcher: descriptors must be CV_8U (binary) or CV_32F");

  const bool binary = query.type() == CV_8U;
  std::vector<std::vector<cv::DMatch>> knn;
  if (options_.algorithm == MatchAlgorithm::kFlann) {
    // LSH: 12 tables of 20-bit keys probed at 2 levels, OpenCV's suggested start for ORB.
    cv::Ptr<cv::flann::IndexParams> index;
    if (binary)
      index = cv::makePtr<cv::flann::LshIndexParams>(12, 20, 2);
    else
      index = cv::makePtr<cv::flann::KDTreeIndexParams>(4);
    cv::FlannBasedMatcher flann(index, cv::makePtr<cv::flann::SearchParams>(options_.flann_checks));
    flann.knnMatch(query, train, knn, 2);
  } else {
    cv::BFMatcher bf(binary ? cv::NORM_HAMMING : cv::NORM_L2);
    bf.knnMatch(query, train, knn, 2);
  }
  for (const auto& m : knn) {
    if (m.empty()) continue;
    if (m.size() == 2 && options_.ratio < 1 && !(m[0].distance < options_.ratio * m[1].distance))
      continue;
    out.push_back(m[0]);
  }
  s.after_ratio = out.size();
  if (out.empty()) return out;
  float best = out.front().distance;
  for (const auto& m : out) best = std::min(best, m.distance);
  s.best_distance = best;
  if (options_.min_distance_factor > 0) {
    const double limit = std::max(options_.min_distance_factor * best, options_.min_distance_floor);
    out.erase(std::remove_if(out.begin(), out.end(),
                             [&](const cv::DMatch& m) { return m.distance > limit; }),
              out.end());
  }
  s.after_min_distance = out.size();
  return out;
}

}  // namespace tessera::visual_slam
