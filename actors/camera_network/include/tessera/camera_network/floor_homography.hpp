// Floor-plane calibration of an environment camera from the robot's own motion
// (docs/algorithms.md#camera-network-calibration): pairs (marker position on the floor [m], in a
// submap's frame; marker pixel [px]) give the camera's floor -> pixel homography H, so that
// [u v 1]^T ~ H [x y 1]^T. No checkerboard: the floor points are the SLAM estimate of the marker
// while the robot drives under the camera.
//
// Estimation: RANSAC over minimal sets (OpenCV), then Gauss-Newton on the inliers' pixel
// reprojection error in normalised coordinates (floor points centred and scaled, pixels too),
// which also gives the covariance of H's 8 free parameters (from the claimed pixel noise, or the
// residual when that is larger). A set that cannot pin a homography is refused with the reason:
// too few pairs, points on a line (straight-line motion), too little of the image covered, a
// badly conditioned system, too few inliers or a large residual.
//
// Plain data in, plain data out; deterministic (RANSAC's generator is seeded).
#pragma once

#include <tessera/config/config_check.hpp>

#include <Eigen/Core>

#include <optional>
#include <string>
#include <vector>

namespace tessera::camera_network {

/// One sighting used for calibration: where the marker was on the floor and where it was seen.
struct FloorPixelPair {
  Eigen::Vector2d floor = Eigen::Vector2d::Zero();  ///< [m] marker in the calibration frame
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();  ///< [px] (u = column, v = row)
};

struct FloorHomographyOptions {
  int min_pairs = 30;                ///< fewer pairs are refused
  double ransac_threshold_px = 8.0;  ///< inlier reprojection distance [px]
  double min_inlier_fraction = 0.6;  ///< refuse when fewer pairs are inliers
  double min_spread_m = 0.3;         ///< refuse when the floor points' minor-axis std is below
  double min_coverage = 0.03;        ///< refuse when the inliers' hull covers less of the image
  double max_condition = 1e7;        ///< refuse a normalised design matrix worse than this
  double max_rms_px = 4.0;           ///< refuse a refined reprojection RMS above this [px]
  /// Std of one rigid error shared by all the floor points (the SLAM placing the whole visit in
  /// its submap): [m] per axis and [rad] about the points' centroid; added to the covariance
  /// (the residuals cannot show it). 0 = the floor points' frame is exact.
  double anchor_std_m = 0.0;
  double anchor_std_rad = 0.0;

  template <class V>
  void visit(V& v) {
    v("min_pairs", min_pairs, "refuse a calibration from fewer (floor, pixel) pairs");
    v("ransac_threshold_px", ransac_threshold_px, "RANSAC inlier reprojection distance [px]");
    v("min_inlier_fraction", min_inlier_fraction, "refuse when fewer pairs are inliers, (0, 1]");
    v("min_spread_m", min_spread_m,
      "refuse when the floor points' spread across their main direction (std) is below this "
      "(straight-line motion) [m]");
    v("min_coverage", min_coverage,
      "refuse when the inlier pixels' convex hull covers less of the image, [0, 1]");
    v("max_condition", max_condition,
      "refuse when the normalised system's condition number exceeds this");
    v("max_rms_px", max_rms_px, "refuse when the refined reprojection RMS exceeds this [px]");
    v("anchor_std_m", anchor_std_m,
      "std of a shift shared by all the floor points (where the SLAM put the visit) [m], added "
      "to the calibration's covariance");
    v("anchor_std_rad", anchor_std_rad,
      "std of a rotation shared by all the floor points, about their centroid [rad]");
  }
  ConfigCheck check() const;
};

/// What a calibration attempt measured, whether or not it was accepted.
struct FloorHomographyQuality {
  int pairs = 0;
  int inliers = 0;
  double rms_px = 0;     ///< inliers' reprojection RMS after refinement [px]
  double coverage = 0;   ///< inlier pixels' convex hull area / image area
  double condition = 0;  ///< σ_max / σ_8 of the normalised DLT matrix (large = ill-posed)
  double spread_m = 0;   ///< floor points' std across their main direction [m]
};

/// An accepted calibration: the homography and what is needed to propagate its uncertainty.
struct FloorHomography {
  Eigen::Matrix3d h = Eigen::Matrix3d::Identity();  ///< floor [m] -> pixel [px], h(2,2) = 1
  /// Normalisations used by the refinement: H = pixel_norm⁻¹ · Hn · floor_norm with Hn(2,2) = 1;
  /// `covariance` is that of Hn's other 8 entries, row-major.
  Eigen::Matrix3d floor_norm = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d pixel_norm = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d hn = Eigen::Matrix3d::Identity();
  Eigen::Matrix<double, 8, 8> covariance = Eigen::Matrix<double, 8, 8>::Zero();
  FloorHomographyQuality quality;

  /// Pixel of a floor point; nullopt behind the camera.
  std::optional<Eigen::Vector2d> project(const Eigen::Vector2d& floor) const;
  /// Floor point of a pixel (nullopt when the pixel's ray misses the floor plane).
  std::optional<Eigen::Vector2d> floorPoint(const Eigen::Vector2d& pixel) const;
  /// The same homography with Hn's 8 parameters moved by `delta` (for uncertainty propagation).
  FloorHomography perturbed(const Eigen::Matrix<double, 8, 1>& delta) const;
};

struct FloorHomographyResult {
  std::optional<FloorHomography> homography;  ///< set when accepted
  std::string refusal;                        ///< why not, when refused
  FloorHomographyQuality quality;
};

/// Calibrates from `pairs`. `image_width`, `image_height` [px] > 0 (for coverage);
/// `pixel_std` [px] > 0 is the detector's claimed noise. Never throws for bad data: non-finite
/// pairs are dropped before anything else (counted out of `pairs`), and every other problem is a
/// refusal. Throws std::invalid_argument for bad options or image size.
FloorHomographyResult estimateFloorHomography(const std::vector<FloorPixelPair>& pairs,
                                              int image_width, int image_height, double pixel_std,
                                              const FloorHomographyOptions& options);

}  // namespace tessera::camera_network
