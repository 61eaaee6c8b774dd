// FeatureMatcher: descriptor matching between two frames
// (docs/algorithms.md#rgb-d-visual-odometry).
//
// Two nearest neighbours per query descriptor, by brute force (the default; OpenCV's BFMatcher:
// Hamming for binary ORB descriptors, L2 for SIFT's float ones) or approximately by FLANN
// (OpenCV's FlannBasedMatcher: multi-probe LSH for binary descriptors, randomised KD-trees for
// float ones; the index is built per call on the train side), then
//   1. the ratio test: keep a match when best < ratio * second best;
//   2. the thesis's minimum-distance filter: drop matches farther than
//      max(min_distance_factor * (best distance of all matches), min_distance_floor), which
//      removes most remaining false matches before RANSAC.
// Distances are in the descriptor's unit (bits for ORB, L2 for SIFT).
#pragma once

#include <opencv2/core.hpp>

#include <array>
#include <cstddef>
#include <utility>
#include <vector>

namespace tessera::visual_slam {

/// How the two nearest neighbours are found.
enum class MatchAlgorithm { kBruteForce, kFlann };
constexpr std::array<std::pair<const char*, MatchAlgorithm>, 2> optionNames(MatchAlgorithm) {
  return {{{"brute_force", MatchAlgorithm::kBruteForce}, {"flann", MatchAlgorithm::kFlann}}};
}

struct FeatureMatcherOptions {
  MatchAlgorithm algorithm = MatchAlgorithm::kBruteForce;
  int flann_checks = 32;  ///< FLANN: leaves searched per query (more: slower, nearer exact)
  double ratio = 0.8;     ///< Lowe's ratio test; 1 disables
  double min_distance_factor = 4.0;  ///< k of the minimum-distance filter; 0 disables
  double min_distance_floor = 30.0;  ///< the filter never drops below this distance

  template <class V>
  void visit(V& v) {
    v("match_algorithm", algorithm,
      "nearest neighbours: brute_force (exact) or flann (LSH for ORB, KD-trees for SIFT)");
    v("flann_checks", flann_checks, "FLANN: leaves searched per query");
    v("match_ratio", ratio, "ratio test: best < ratio x second best (1 disables)");
    v("min_distance_factor", min_distance_factor,
      "drop matches farther than this x the best match's distance (0 disables)");
    v("min_distance_floor", min_distance_floor,
      "the minimum-distance filter keeps every match closer than this [descriptor units]");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

struct MatchStats {
  std::size_t queries = 0;      ///< query descriptors
  std::size_t after_ratio = 0;  ///< matches that passed the ratio test
  std::size_t after_min_distance = 0;
  double best_distance = 0;
};

/// Distance between row i of `a` and row j of `b` (same type: Hamming for CV_8U, L2 for CV_32F).
double descriptorDistance(const cv::Mat& a, int i, const cv::Mat& b, int j);

class FeatureMatcher {
 public:
  explicit FeatureMatcher(const FeatureMatcherOptions& options = {});

  /// Matches of each `query` row to a `train` row (DMatch::queryIdx / trainIdx), sorted by query.
  /// Empty when either side is empty; throws std::invalid_argument when the descriptor types or
  /// widths differ.
  std::vector<cv::DMatch> match(const cv::Mat& query, const cv::Mat& train,
                                MatchStats* stats = nullptr) const;

  const FeatureMatcherOptions& options() const { return options_; }

 private:
  FeatureMatcherOptions options_;
};

}  // namespace tessera::visual_slam
