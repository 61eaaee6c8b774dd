// Camera localisation and the revisit transform fit: see camera_localization.hpp.
#include <tessera/camera_network/camera_localization.hpp>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <Eigen/LU>

#include "fixed_text.hpp"

#include <cmath>

namespace tessera::camera_network {

using detail::fixed;

ConfigCheck MapTransformOptions::check() const {
  ConfigCheck c;
  c.require(min_points >= 2, "min_points", "must be >= 2", min_points)
      .nonNegative("min_extent_m", min_extent_m)
      .positive("max_rms_m", max_rms_m)
      .positive("min_point_std_m", min_point_std_m);
  return c;
}

std::optional<MarkerFix> localizeMarker(const FloorHomography& calibration,
                                        const Eigen::Vector2d& pixel, double pixel_std) {
  if (!pixel.allFinite() || !std::isfinite(pixel_std) || pixel_std < 0) return std::nullopt;
  const auto p = calibration.floorPoint(pixel);
  if (!p) return std::nullopt;
  MarkerFix fix;
  fix.position = *p;
  // Pixel noise: central differences of the inverse map (half a pixel either side).
  Eigen::Matrix2d ju;
  for (int k = 0; k < 2; ++k) {
    Eigen::Vector2d d = Eigen::Vector2d::Zero();
    d(k) = 0.5;
    const auto a = calibration.floorPoint(pixel + d), b = calibration.floorPoint(pixel - d);
    if (!a || !b) return std::nullopt;
    ju.col(k) = (*a - *b) / 1.0;
  }
  fix.covariance = pixel_std * pixel_std * ju * ju.transpose();
  // Calibration uncertainty: derivative with respect to Hn's 8 entries.
  Eigen::Matrix<double, 2, 8> jh;
  for (int k = 0; k < 8; ++k) {
    const double step = 1e-6 * std::max(1.0, std::abs(calibration.hn(k / 3, k % 3)));
    Eigen::Matrix<double, 8, 1> d = Eigen::Matrix<double, 8, 1>::Zero();
    d(k) = step;
    const auto a = calibration.perturbed(d).floorPoint(pixel);
    const auto b = calibration.perturbed(-d).floorPoint(pixel);
    if (!a || !b) return std::nullopt;
    jh.col(k) = (*a - *b) / (2 * step);
  }
  fix.covariance += jh * calibration.covariance * jh.transpose();
  return fix;
}

namespace camera_localization_detail {

/// Marker pose (x, y, θ) from the corners' floor points under `h`; nullopt as localizeMarkerPose.
std::optional<Eigen::Vector3d> markerPose(const FloorHomography& h,
                                          const std::array<Eigen::Vector2d, 4>& corners) {
  std::array<Eigen::Vector2d, 4> f;
  for (std::size_t k = 0; k < 4; ++k) {
    const auto p = h.floorPoint(corners[k]);
    if (!p) return std::nullopt;
    f[k] = *p;
  }
  const Eigen::Vector2d centre = 0.25 * (f[0] + f[1] + f[2] + f[3]);
  const Eigen::Vector2d forward = 0.5 * (f[0] + f[1]) - 0.5 * (f[2] + f[3]);
  if (!(forward.norm() > 1e-6)) return std::nullopt;
  return Eigen::Vector3d(centre.x(), centre.y(), std::atan2(forward.y(), forward.x()));
}

Eigen::Vector3d difference(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return {a.x() - b.x(), a.y() - b.y(), angleDiff(a.z(), b.z())};
}

}  // namespace camera_localization_detail

std::optional<MarkerPoseFix> localizeMarkerPose(const FloorHomography& calibration,
                                                const std::array<Eigen::Vector2d, 4>& corners,
                                                double pixel_std) {
  namespace d = camera_localization_detail;
  if (!std::isfinite(pixel_std) || pixel_std < 0) return std::nullopt;
  for (const auto& c : corners)
    if (!c.allFinite()) return std::nullopt;
  const auto mid = d::markerPose(calibration, corners);
  if (!mid) return std::nullopt;
  // Pixel noise: each corner coordinate moved half a pixel either side.
  Eigen::Matrix<double, 3, 8> ju;
  for (int k = 0; k < 8; ++k) {
    auto plus = corners, minus = corners;
    plus[k / 2](k % 2) += 0.5;
    minus[k / 2](k % 2) -= 0.5;
    const auto a = d::markerPose(calibration, plus), b = d::markerPose(calibration, minus);
    if (!a || !b) return std::nullopt;
    ju.col(k) = d::difference(*a, *b);
  }
  // Calibration uncertainty: derivative with respect to Hn's 8 entries.
  Eigen::Matrix<double, 3, 8> jh;
  for (int k = 0; k < 8; ++k) {
    const double step = 1e-6 * std::max(1.0, std::abs(calibration.hn(k / 3, k % 3)));
    Eigen::Matrix<double, 8, 1> delta = Eigen::Matrix<double, 8, 1>::Zero();
    delta(k) = step;
    const auto a = d::markerPose(calibration.perturbed(delta), corners);
    const auto b = d::markerPose(calibration.perturbed(-delta), corners);
    if (!a || !b) return std::nullopt;
    jh.col(k) = d::difference(*a, *b) / (2 * step);
  }
  MarkerPoseFix fix;
  fix.pose = Pose2(mid->x(), mid->y(), mid->z());
  fix.covariance =
      pixel_std * pixel_std * ju * ju.transpose() + jh * calibration.covariance * jh.transpose();
  fix.covariance = 0.5 * (fix.covariance + fix.covariance.transpose()).eval();
  return fix;
}

Pose2 closedFormRigidFit(const std::vector<Eigen::Vector2d>& child,
                         const std::vector<Eigen::Vector2d>& parent) {
  const double n = static_cast<double>(child.size());
  Eigen::Vector2d cp = Eigen::Vector2d::Zero(), cc = Eigen::Vector2d::Zero();
  for (std::size_t k = 0; k < child.size(); ++k) {
    cp += parent[k];
    cc += child[k];
  }
  cp /= n;
  cc /= n;
  double sdot = 0, scross = 0;
  for (std::size_t k = 0; k < child.size(); ++k) {
    const Eigen::Vector2d a = child[k] - cc, b = parent[k] - cp;
    sdot += a.dot(b);
    scross += a.x() * b.y() - a.y() * b.x();
  }
  const double theta = std::atan2(scross, sdot);
  return Pose2(cp - Eigen::Rotation2Dd(theta) * cc, theta);
}

MapTransformResult fitMapTransform(const std::vector<PointCorrespondence>& input,
                                   const MapTransformOptions& options) {
  options.check().throwIfBad("map transform fit");
  std::vector<PointCorrespondence> pts;
  for (const auto& p : input)
    if (p.parent.allFinite() && p.child.allFinite() && p.parent_covariance.allFinite() &&
        p.child_covariance.allFinite())
      pts.push_back(p);
  MapTransformResult result;
  auto& m = result.measured;
  m.points = static_cast<int>(pts.size());
  if (m.points < options.min_points) {
    result.refusal = "too few sightings: " + std::to_string(m.points) + " (need " +
                     std::to_string(options.min_points) + ")";
    return result;
  }
  for (std::size_t a = 0; a < pts.size(); ++a)
    for (std::size_t b = a + 1; b < pts.size(); ++b)
      m.extent_m = std::max(m.extent_m, (pts[a].child - pts[b].child).norm());
  if (m.extent_m < options.min_extent_m) {
    result.refusal = "the sightings span " + fixed(m.extent_m, 2) + " m (need " +
                     fixed(options.min_extent_m, 2) + " m of motion for a heading)";
    return result;
  }
  // Closed form (unweighted) for the start.
  std::vector<Eigen::Vector2d> child, parent;
  for (const auto& p : pts) {
    child.push_back(p.child);
    parent.push_back(p.parent);
  }
  Pose2 t = closedFormRigidFit(child, parent);

  // Gauss-Newton with each residual weighted by its combined covariance.
  const double floor2 = options.min_point_std_m * options.min_point_std_m;
  Eigen::Matrix3d info;
  double sse = 0;
  for (int it = 0; it < 10; ++it) {
    info.setZero();
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    sse = 0;
    const Eigen::Matrix2d r = t.rotation();
    Eigen::Matrix2d dr;
    dr << -r(1, 0), -r(0, 0), r(0, 0), -r(1, 0);
    for (const auto& p : pts) {
      const Eigen::Vector2d e = r * p.child + t.translation() - p.parent;
      const Eigen::Matrix2d c = r * p.child_covariance * r.transpose() + p.parent_covariance +
                                2 * floor2 * Eigen::Matrix2d::Identity();
      const Eigen::Matrix2d w = c.inverse();
      Eigen::Matrix<double, 2, 3> j;
      j.leftCols<2>().setIdentity();
      j.col(2) = dr * p.child;
      info += j.transpose() * w * j;
      g += j.transpose() * w * e;
      sse += e.squaredNorm();
    }
    const Eigen::Vector3d step = -info.ldlt().solve(g);
    t = Pose2(t.x + step(0), t.y + step(1), t.theta + step(2));
    if (step.norm() < 1e-10) break;
  }
  sse = 0;
  for (const auto& p : pts) sse += (t * p.child - p.parent).squaredNorm();
  m.transform = t;
  m.rms_m = std::sqrt(sse / m.points);
  m.covariance = info.ldlt().solve(Eigen::Matrix3d::Identity());
  if (m.rms_m > options.max_rms_m) {
    result.refusal = "camera and SLAM positions disagree: RMS " + fixed(m.rms_m, 3) +
                     " m (at most " + fixed(options.max_rms_m, 3) + " m)";
    return result;
  }
  result.fit = m;
  return result;
}

}  // namespace tessera::camera_network
