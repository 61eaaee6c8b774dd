#include <tessera/geometry/floor_camera_calibration.hpp>

#include <Eigen/SVD>

#include <array>
#include <charconv>
#include <cmath>

namespace tessera {

namespace floor_camera_calibration_detail {

/// Shortest text that reads back as the same double.
std::string numberText(double v) {
  std::array<char, 64> buf{};
  const auto res = std::to_chars(buf.data(), buf.data() + buf.size(), v);
  return std::string(buf.data(), res.ptr);
}

bool finiteNonNegative(double v) {
  return std::isfinite(v) && v >= 0;
}

}  // namespace floor_camera_calibration_detail

double homographyInverseCondition(const Eigen::Matrix3d& h) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(h);
  const Eigen::Vector3d s = svd.singularValues();
  return s(0) > 0 ? s(2) / s(0) : 0.0;
}

std::string floorCameraCalibrationProblem(const FloorCameraCalibration& c) {
  using floor_camera_calibration_detail::finiteNonNegative;
  using floor_camera_calibration_detail::numberText;
  if (c.camera < 0) return "id: must be >= 0, got " + std::to_string(c.camera);
  if (c.submap < 0) return "submap: must be >= 0, got " + std::to_string(c.submap);
  if (!c.floor_to_pixel.allFinite()) return "homography: must be 9 finite numbers";
  if (const double ic = homographyInverseCondition(c.floor_to_pixel);
      !(ic > kMinHomographyInverseCondition))
    return "homography: is singular (σ_min/σ_max = " + numberText(ic) +
           "); expected an invertible floor -> pixel homography";
  if (!finiteNonNegative(c.rms_px))
    return "rms_px: must be a finite number >= 0, got " + numberText(c.rms_px);
  if (!(finiteNonNegative(c.coverage) && c.coverage <= 1))
    return "coverage: must be in 0..1, got " + numberText(c.coverage);
  if (!finiteNonNegative(c.condition))
    return "condition: must be a finite number >= 0, got " + numberText(c.condition);
  if (c.pairs < 0) return "pairs: must be >= 0, got " + std::to_string(c.pairs);
  if (c.inliers < 0 || c.inliers > c.pairs)
    return "inliers: must be in 0..pairs (" + std::to_string(c.pairs) + "), got " +
           std::to_string(c.inliers);
  return {};
}

}  // namespace tessera
