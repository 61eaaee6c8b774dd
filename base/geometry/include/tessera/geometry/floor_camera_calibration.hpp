// An environment camera's floor-plane calibration as it is stored: the floor -> pixel homography
// of one camera in the SLAM submap it was calibrated in, with the quality figures of its estimate
// (docs/algorithms.md#camera-network-calibration). One type and one validity check for every place
// that keeps calibrations (the calibrations file, saved SLAM states, the map assembler), so they
// accept and refuse the same records.
//
// Units: floor points in metres in the submap's frame, pixels in the camera's image.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <string>

namespace tessera {

struct FloorCameraCalibration {
  int camera = 0;             ///< camera id, >= 0 (stored as `id`)
  int submap = 0;             ///< the submap whose frame the floor points are in, >= 0
  std::int64_t stamp_ns = 0;  ///< end of the visit it was calibrated from
  /// floor [m, submap frame] -> pixel [px]: [u v 1]ᵀ ~ H [x y 1]ᵀ; finite, non-singular
  Eigen::Matrix3d floor_to_pixel = Eigen::Matrix3d::Identity();
  double rms_px = 0;     ///< inliers' reprojection RMS [px], >= 0
  double coverage = 0;   ///< inlier pixels' convex hull / image area, 0..1
  double condition = 0;  ///< σ_max / σ_8 of the normalised DLT matrix, >= 0
  int pairs = 0;         ///< (marker position, pixel) pairs, >= 0
  int inliers = 0;       ///< 0..pairs

  bool operator==(const FloorCameraCalibration&) const = default;
};

/// σ_min / σ_max of a homography (0 for the zero matrix).
double homographyInverseCondition(const Eigen::Matrix3d& h);

/// At or below this σ_min / σ_max a homography is singular: it maps no pixel back to the floor.
inline constexpr double kMinHomographyInverseCondition = 1e-12;

/// Empty when `c` is valid on its own, else "KEY: PROBLEM" with KEY the stored key (id, submap,
/// homography, rms_px, coverage, condition, pairs, inliers), e.g.
/// "homography: is singular (σ_min/σ_max = 0); expected an invertible floor -> pixel homography".
std::string floorCameraCalibrationProblem(const FloorCameraCalibration& c);

}  // namespace tessera
