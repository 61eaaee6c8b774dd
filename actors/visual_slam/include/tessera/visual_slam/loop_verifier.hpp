// LoopVerifier: geometric verification of a bag-of-words loop candidate
// (docs/algorithms.md#loop-closure).
//
// Given the query keyframe and a candidate (each: pixels, 256-bit ORB descriptors, 3D points in
// its own camera frame, and the FeatureVector of a Vocabulary::transform at `direct_depth`):
//   1. Matching through the direct index (DBoW2's / ORB-SLAM's SearchByBoW): only features under
//      the same vocabulary node are compared; a query feature keeps its nearest candidate feature
//      when the Hamming distance is <= max_distance and < ratio x the second nearest; each
//      candidate feature is used once (the closer match wins). Only candidate features with a 3D
//      point take part.
//   2. RANSAC PnP + refinement (PoseEstimator) of the candidate's 3D points against the query's
//      pixels (the query's depths enter the refinement's depth residual): the pose of the
//      candidate's camera frame in the query's camera, query_from_candidate.
//   3. 3D check: an inlier whose query pixel has a 3D point must land within
//      max_point_distance + max_point_distance_rel * z of it (depth noise grows with z).
//   4. With align_3d, the rigid 3D-3D fit (Eigen::umeyama) of the inliers that passed the 3D
//      check: depths fix the pose better than a few dozen reprojections
//      (docs/algorithms.md#loop-closure). It is the output pose, and how far it lies from the PnP
//      pose says how well the two independent estimates agree.
//   5. Accepted when inliers >= min_inliers, inliers / matches >= min_inlier_ratio, the RMS
//      reprojection error <= max_rms_px, the 3D-consistent share of the inliers with depth
//      >= min_depth_agreement, the inliers cover >= min_coverage of the image (cells of a 4 x 4
//      grid holding one) and, with align_3d, the PnP and 3D poses agree within
//      max_pose_disagreement_m / _rad: a few inliers bunched in one corner, or a scene that fixes
//      the pose badly, give a pose that is right in place but wrong by decimetres.
// Output: candidate_from_query (the query keyframe's pose in the candidate's frame, as a
// KeyframeConstraint from the candidate to the query carries it) and its covariance over
// (x y z rx ry rz) of the right perturbation T = T^ exp(d), propagated from the PnP refinement's
// covariance (also with align_3d) and floored at min_sigma_* (the refinement's covariance ignores
// outliers that got through and is optimistic).
//
// Units: pixels, metres, radians. Stateless and thread-safe.
#pragma once

#include <tessera/visual_slam/camera.hpp>
#include <tessera/visual_slam/pose_estimator.hpp>
#include <tessera/visual_slam/vocabulary.hpp>

#include <opencv2/core.hpp>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstddef>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tessera::visual_slam {

struct LoopVerifierOptions {
  /// Depth of the direct-index nodes (0 = root: every feature compared with every other).
  /// ORB-SLAM uses 2 (4 levels up in its 6-level tree) with 0.75 and 50 bits below; on 7-Scenes
  /// keyframes (docs/benchmarks.md) that left ~20 matches a revisit, too few for PnP, so we split
  /// less (1: k buckets), and accept a looser ratio and distance; verification keeps precision.
  int direct_depth = 1;
  double ratio = 0.8;              ///< ratio test of the matching (Lowe's 0.8)
  int max_distance = 64;           ///< [bits] a quarter of the 256 bits
  int min_matches = 20;            ///< fewer matches: no PnP (ORB-SLAM's 20 before its Sim3 RANSAC)
  int min_inliers = 25;            ///< PnP inliers of an accepted loop (no false loop on 7-Scenes)
  double min_inlier_ratio = 0.35;  ///< inliers / matches
  double max_rms_px = 2.0;         ///< [px] RMS reprojection error of the inliers
  double max_point_distance = 0.05;      ///< [m] 3D check: allowed distance at z = 0 ...
  double max_point_distance_rel = 0.03;  ///< ... plus this fraction of the query depth
  double min_depth_agreement = 0.8;      ///< share of inliers with depth passing the 3D check
  double min_coverage = 0.0;             ///< share of the 4 x 4 image cells holding a query inlier
  /// [m] PnP pose vs 3D fit, translation. True loops disagreed by at most 0.135 m (simulated
  /// office, 493 loops) and 0.114 m (7-Scenes); the one false loop of the office, 12 cm off,
  /// by 0.164 m (docs/benchmarks.md, loop closure).
  double max_pose_disagreement_m = 0.15;
  double max_pose_disagreement_rad = 0.1;  ///< [rad] (true loops: at most 0.043)
  double min_sigma_translation = 0.01;     ///< [m] floor of the output's standard deviations
  double min_sigma_rotation = 0.005;       ///< [rad]
  bool align_3d = true;  ///< output pose: rigid 3D-3D fit of the inliers (false: the PnP pose)
  PoseEstimatorOptions pnp = defaultPnp();

  static PoseEstimatorOptions defaultPnp() {
    PoseEstimatorOptions o;
    o.min_inlier_ratio = 0.2;  // loop matches hold more outliers than tracking matches
    o.max_iterations = 500;
    o.min_inliers = 12;
    return o;
  }

  template <class V>
  void visit(V& v) {
    v("direct_depth", direct_depth, "vocabulary depth of the direct index used for matching");
    v("ratio", ratio, "ratio test of the matching: best < ratio x second best");
    v("max_distance", max_distance, "largest Hamming distance of a match [bits]");
    v("min_matches", min_matches, "fewest matches to try PnP");
    v("min_inliers", min_inliers, "fewest PnP inliers of an accepted loop");
    v("min_inlier_ratio", min_inlier_ratio, "smallest inliers / matches of an accepted loop");
    v("max_rms_px", max_rms_px, "largest RMS reprojection error of the inliers [px]");
    v("max_point_distance", max_point_distance,
      "3D check: largest distance between matched points at zero depth [m] ...");
    v("max_point_distance_rel", max_point_distance_rel, "... plus this fraction of the depth");
    v("min_depth_agreement", min_depth_agreement,
      "smallest share of inliers with depth that pass the 3D check");
    v("min_coverage", min_coverage,
      "smallest share of the 4 x 4 image cells that hold a query inlier");
    v("max_pose_disagreement_m", max_pose_disagreement_m,
      "with align_3d: largest translation between the PnP pose and the 3D fit [m]");
    v("max_pose_disagreement_rad", max_pose_disagreement_rad,
      "with align_3d: largest rotation between the PnP pose and the 3D fit [rad]");
    v("min_sigma_translation", min_sigma_translation,
      "floor of the loop's translation standard deviation [m]");
    v("min_sigma_rotation", min_sigma_rotation,
      "floor of the loop's rotation standard deviation [rad]");
    v("align_3d", align_3d,
      "output the rigid 3D-3D fit of the PnP inliers' points instead of the PnP pose");
    v("pnp", pnp, "RANSAC PnP and refinement of the candidate's points against the query");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

/// One keyframe as the verifier reads it. Index i is the same feature everywhere.
struct LoopView {
  std::vector<Eigen::Vector2d> pixels;  ///< [px]
  cv::Mat descriptors;                  ///< CV_8UC1, 32 bytes a row
  std::vector<Eigen::Vector3d> points;  ///< camera frame [m]; NaN where there is none
  FeatureVector features;               ///< Vocabulary::transform at options.direct_depth

  std::size_t size() const { return pixels.size(); }
  /// "" when usable, else why not (sizes that disagree, wrong descriptor type, non-finite pixel).
  std::string check() const;
};

enum class LoopRejection {
  kNone,
  kTooFewMatches,
  kPnpFailed,
  kTooFewInliers,
  kLowInlierRatio,
  kHighError,
  kDepthDisagrees,
  kLowCoverage,
  kPoseDisagrees,
};
std::string_view rejectionName(LoopRejection r);

struct LoopVerification {
  bool accepted = false;
  LoopRejection rejection = LoopRejection::kTooFewMatches;
  int matches = 0;
  int inliers = 0;
  double inlier_ratio = 0;
  double rms_px = 0;
  double depth_agreement = 0;        ///< share of inliers with depth passing the 3D check
  double coverage = 0;               ///< share of the 4 x 4 image cells holding a query inlier
  double fit_rms_m = 0;              ///< [m] RMS residual of the 3D fit (0 without one)
  double pose_disagreement_m = 0;    ///< [m] PnP pose vs 3D fit (0 without one)
  double pose_disagreement_rad = 0;  ///< [rad]
  Eigen::Isometry3d candidate_from_query = Eigen::Isometry3d::Identity();
  /// Over (x y z rx ry rz) of candidate_from_query (right perturbation), floored.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
  std::vector<std::pair<int, int>> inlier_pairs;  ///< (query, candidate) feature indices
};

/// Direct-index matching alone: (query, candidate) index pairs, candidates with a 3D point only.
std::vector<std::pair<int, int>> matchByDirectIndex(const LoopView& query,
                                                    const LoopView& candidate, double ratio,
                                                    int max_distance);

class LoopVerifier {
 public:
  /// `camera`: intrinsics of the query's pixels. Throws std::invalid_argument for bad options or
  /// intrinsics.
  LoopVerifier(const LoopVerifierOptions& options, const PinholeCamera& camera);

  /// Never throws for bad geometry; views that fail check() give kTooFewMatches.
  LoopVerification verify(const LoopView& query, const LoopView& candidate) const;

  const LoopVerifierOptions& options() const { return options_; }

 private:
  LoopVerifierOptions options_;
  PinholeCamera camera_;
  PoseEstimator estimator_;
};

}  // namespace tessera::visual_slam
