// PoseEstimator: the camera pose from 3D points and their pixels in the current image
// (docs/algorithms.md#rgb-d-visual-odometry).
//
//   1. RANSAC PnP (cv::solvePnPRansac). The iteration cap is the thesis's
//      k = log(1 - p) / log(1 - w^m) with p = confidence (0.995), w = min_inlier_ratio (the worst
//      inlier ratio we plan for) and m the minimal sample of the method (4 for P3P/AP3P, whose
//      fourth point picks among the solutions; 5 for OpenCV's EPnP kernel). OpenCV lowers the
//      count by the same formula as better hypotheses raise w.
//   2. Motion-only refinement (Ceres, Levenberg-Marquardt) of the pose over the RANSAC inliers,
//      minimising reprojection errors (plus, where the current frame measured a depth, a
//      disparity residual; depth_baseline) under a Huber loss of width huber_delta pixels.
//   3. Inliers re-counted over all correspondences at the refined pose; their RMS reprojection
//      error, and the pose covariance (J^T J)^-1 s^2 of the refinement (s^2: residual variance).
//
// Poses: camera_from_world maps world points into the camera's optical frame (x right, y down,
// z forward); the 3D points are in the world frame [m], pixels in the image [px], no distortion.
// Stateless and thread-safe.
#pragma once

#include <tessera/visual_slam/camera.hpp>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace tessera::visual_slam {

enum class PnpMethod { kAp3p, kEpnp, kIterative };
constexpr std::array<std::pair<const char*, PnpMethod>, 3> optionNames(PnpMethod) {
  return {{{"ap3p", PnpMethod::kAp3p},
           {"epnp", PnpMethod::kEpnp},
           {"iterative", PnpMethod::kIterative}}};
}

struct PoseEstimatorOptions {
  PnpMethod method = PnpMethod::kAp3p;
  double confidence = 0.995;        ///< p of the iteration formula (the thesis's value)
  double min_inlier_ratio = 0.3;    ///< w of the iteration formula: the cap covers this ratio
  int max_iterations = 2000;        ///< hard cap on top of the formula
  double reprojection_error = 3.0;  ///< [px] inlier threshold
  int min_inliers = 6;              ///< fewer RANSAC inliers: no pose
  bool refine = true;               ///< the Ceres refinement
  double huber_delta = 1.5;         ///< [px] Huber loss width of the refinement
  int refine_iterations = 10;
  /// [m] With measured depths, the refinement adds a disparity residual fx b / z (b this
  /// baseline; ORB-SLAM2's RGB-D residual, 0.08 m as a Kinect's projector-camera distance):
  /// depth then constrains the pose along the optical axis, less the farther it is. 0 = off.
  double depth_baseline = 0.08;

  template <class V>
  void visit(V& v) {
    v("pnp_method", method, "RANSAC PnP minimal solver");
    v("ransac_confidence", confidence, "p in k = log(1-p)/log(1-w^m)");
    v("ransac_min_inlier_ratio", min_inlier_ratio, "w in k = log(1-p)/log(1-w^m)");
    v("ransac_max_iterations", max_iterations, "cap on the RANSAC iterations");
    v("reprojection_error", reprojection_error, "inlier threshold [px]");
    v("pnp_min_inliers", min_inliers, "fewest inliers for a pose");
    v("refine", refine, "refine the pose over the inliers (Ceres, Huber loss)");
    v("huber_delta", huber_delta, "Huber loss width of the refinement [px]");
    v("refine_iterations", refine_iterations, "iterations of the refinement");
    v("depth_baseline", depth_baseline,
      "virtual stereo baseline of the depth residual in the refinement [m] (0 = off)");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

/// k = log(1 - p) / log(1 - w^m), rounded up (at least 1); `cap` when w^m underflows.
int ransacIterations(double p, double w, int m, int cap);
/// The minimal sample of OpenCV's RANSAC kernel for `method`.
int minimalSample(PnpMethod method);

struct PoseEstimate {
  bool ok = false;
  std::string failure;  ///< why not, when !ok
  Eigen::Isometry3d camera_from_world = Eigen::Isometry3d::Identity();
  std::vector<int> inliers;  ///< indices into the correspondences
  double rms_px = 0;         ///< RMS reprojection error of the inliers [px]
  /// Covariance of (rotation vector, translation) of camera_from_world [rad, m]; zero when
  /// the refinement was off or singular.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  int ransac_iterations = 0;  ///< the cap given to RANSAC
  int ransac_inliers = 0;     ///< before the refinement
};

class PoseEstimator {
 public:
  /// Throws std::invalid_argument for bad options or intrinsics.
  PoseEstimator(const PoseEstimatorOptions& options, const PinholeCamera& camera);

  /// `points[i]` (world) seen at `pixels[i]`. `guess`, when given, starts the EPnP/iterative
  /// refit and the refinement near it. `depths`, when given, holds the measured depth z [m] at
  /// each pixel (NaN: none) for the refinement's depth residual. Never throws for bad
  /// geometry: !ok with a reason.
  PoseEstimate estimate(const std::vector<Eigen::Vector3d>& points,
                        const std::vector<Eigen::Vector2d>& pixels,
                        const std::optional<Eigen::Isometry3d>& guess = std::nullopt,
                        const std::vector<double>* depths = nullptr) const;

  const PoseEstimatorOptions& options() const { return options_; }

 private:
  PoseEstimatorOptions options_;
  PinholeCamera camera_;
};

}  // namespace tessera::visual_slam
