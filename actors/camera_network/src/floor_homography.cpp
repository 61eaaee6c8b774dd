// Floor-plane homography from (floor, pixel) pairs: see floor_homography.hpp and
// docs/algorithms.md#camera-network-calibration.
#include <tessera/camera_network/floor_homography.hpp>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "fixed_text.hpp"

#include <cmath>
#include <stdexcept>

namespace tessera::camera_network {

using detail::fixed;

ConfigCheck FloorHomographyOptions::check() const {
  ConfigCheck c;
  c.require(min_pairs >= 8, "min_pairs", "must be >= 8", min_pairs)
      .positive("ransac_threshold_px", ransac_threshold_px)
      .require(min_inlier_fraction > 0 && min_inlier_fraction <= 1, "min_inlier_fraction",
               "must be in (0, 1]", min_inlier_fraction)
      .nonNegative("min_spread_m", min_spread_m)
      .probability("min_coverage", min_coverage)
      .positive("max_condition", max_condition)
      .positive("max_rms_px", max_rms_px)
      .nonNegative("anchor_std_m", anchor_std_m)
      .nonNegative("anchor_std_rad", anchor_std_rad);
  return c;
}

namespace {

/// Similarity that moves the points' centroid to the origin and their mean distance to √2.
Eigen::Matrix3d normalisation(const std::vector<Eigen::Vector2d>& points) {
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (const auto& p : points) c += p;
  c /= static_cast<double>(points.size());
  double mean = 0;
  for (const auto& p : points) mean += (p - c).norm();
  mean /= static_cast<double>(points.size());
  const double s = mean > 1e-12 ? std::sqrt(2.0) / mean : 1.0;
  Eigen::Matrix3d t;
  t << s, 0, -s * c.x(), 0, s, -s * c.y(), 0, 0, 1;
  return t;
}

Eigen::Vector2d apply(const Eigen::Matrix3d& h, const Eigen::Vector2d& p) {
  const Eigen::Vector3d q = h * p.homogeneous();
  return q.head<2>() / q.z();
}

double minorSpread(const std::vector<Eigen::Vector2d>& points) {
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (const auto& p : points) c += p;
  c /= static_cast<double>(points.size());
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (const auto& p : points) cov += (p - c) * (p - c).transpose();
  cov /= static_cast<double>(points.size());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
  return std::sqrt(std::max(0.0, eig.eigenvalues()(0)));
}

/// σ_1 / σ_8 of the DLT design matrix of normalised pairs (the 9th is the solution's null space).
double dltCondition(const std::vector<Eigen::Vector2d>& floor_n,
                    const std::vector<Eigen::Vector2d>& pixel_n) {
  Eigen::MatrixXd a(2 * floor_n.size(), 9);
  for (std::size_t i = 0; i < floor_n.size(); ++i) {
    const double x = floor_n[i].x(), y = floor_n[i].y();
    const double u = pixel_n[i].x(), v = pixel_n[i].y();
    a.row(2 * i) << -x, -y, -1, 0, 0, 0, u * x, u * y, u;
    a.row(2 * i + 1) << 0, 0, 0, -x, -y, -1, v * x, v * y, v;
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a);
  const auto& s = svd.singularValues();
  return s(7) > 0 ? s(0) / s(7) : std::numeric_limits<double>::infinity();
}

/// Gauss-Newton on Hn's 8 free entries (Hn(2,2) = 1) minimising the pixel reprojection error of
/// the pairs; leaves J^T J (pixel units) and the sum of squared residuals of the result.
void refine(FloorHomography& out, const std::vector<Eigen::Vector2d>& floor,
            const std::vector<Eigen::Vector2d>& pixel, Eigen::Matrix<double, 8, 8>& jtj,
            double& sse) {
  const double sp = out.pixel_norm(0, 0);  // pixel_n = sp · (pixel − centre)
  const Eigen::Matrix3d pn_inv = out.pixel_norm.inverse();
  std::vector<Eigen::Vector2d> fn(floor.size());
  for (std::size_t i = 0; i < floor.size(); ++i) fn[i] = apply(out.floor_norm, floor[i]);
  auto linearise = [&](const Eigen::Matrix3d& hn, Eigen::Matrix<double, 8, 1>& jtr) {
    jtj.setZero();
    jtr.setZero();
    double e = 0;
    for (std::size_t i = 0; i < fn.size(); ++i) {
      const Eigen::Vector3d f(fn[i].x(), fn[i].y(), 1.0);
      const Eigen::Vector3d qh = hn * f;
      const double un = qh.x() / qh.z(), vn = qh.y() / qh.z();
      const Eigen::Vector2d r = apply(pn_inv, Eigen::Vector2d(un, vn)) - pixel[i];
      e += r.squaredNorm();
      Eigen::Matrix<double, 2, 8> j = Eigen::Matrix<double, 2, 8>::Zero();
      const double w = 1.0 / (qh.z() * sp);
      for (int k = 0; k < 3; ++k) {
        j(0, k) = f(k) * w;
        j(1, 3 + k) = f(k) * w;
      }
      for (int k = 0; k < 2; ++k) {
        j(0, 6 + k) = -un * f(k) * w;
        j(1, 6 + k) = -vn * f(k) * w;
      }
      jtj += j.transpose() * j;
      jtr += j.transpose() * r;
    }
    return e;
  };
  Eigen::Matrix<double, 8, 1> jtr;
  sse = linearise(out.hn, jtr);
  for (int it = 0; it < 20; ++it) {
    const Eigen::Matrix<double, 8, 1> step = -jtj.ldlt().solve(jtr);
    Eigen::Matrix3d trial = out.hn;
    for (int k = 0; k < 8; ++k) trial(k / 3, k % 3) += step(k);
    Eigen::Matrix<double, 8, 1> jtr_trial;
    const double e = linearise(trial, jtr_trial);
    if (!(e < sse)) {
      linearise(out.hn, jtr);  // J^T J back at the kept estimate
      break;
    }
    const bool small = sse - e < 1e-12 * (1 + sse);
    out.hn = trial;
    sse = e;
    jtr = jtr_trial;
    if (small) break;
  }
}

}  // namespace

std::optional<Eigen::Vector2d> FloorHomography::project(const Eigen::Vector2d& floor) const {
  const Eigen::Vector3d q = h * floor.homogeneous();
  if (!(q.z() > 0)) return std::nullopt;
  return Eigen::Vector2d(q.head<2>() / q.z());
}

std::optional<Eigen::Vector2d> FloorHomography::floorPoint(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector3d f = h.inverse() * pixel.homogeneous();
  if (!(std::abs(f.z()) > 1e-15)) return std::nullopt;
  const Eigen::Vector2d p = f.head<2>() / f.z();
  // The pixel's ray meets the floor in front of the camera only if the point projects forward.
  if (!project(p) || !p.allFinite()) return std::nullopt;
  return p;
}

FloorHomography FloorHomography::perturbed(const Eigen::Matrix<double, 8, 1>& delta) const {
  FloorHomography out = *this;
  for (int k = 0; k < 8; ++k) out.hn(k / 3, k % 3) += delta(k);
  out.h = pixel_norm.inverse() * out.hn * floor_norm;
  if (std::abs(out.h(2, 2)) > 1e-12) out.h /= out.h(2, 2);
  return out;
}

FloorHomographyResult estimateFloorHomography(const std::vector<FloorPixelPair>& pairs,
                                              int image_width, int image_height, double pixel_std,
                                              const FloorHomographyOptions& options) {
  options.check().throwIfBad("floor homography");
  if (image_width <= 0 || image_height <= 0)
    throw std::invalid_argument("floor homography: image size must be positive, got " +
                                std::to_string(image_width) + " x " + std::to_string(image_height));
  if (!(pixel_std > 0) || !std::isfinite(pixel_std))
    throw std::invalid_argument("floor homography: pixel_std must be finite and > 0, got " +
                                std::to_string(pixel_std));

  FloorHomographyResult result;
  std::vector<Eigen::Vector2d> floor, pixel;
  for (const auto& p : pairs) {
    if (!p.floor.allFinite() || !p.pixel.allFinite()) continue;
    floor.push_back(p.floor);
    pixel.push_back(p.pixel);
  }
  auto& q = result.quality;
  q.pairs = static_cast<int>(floor.size());
  if (q.pairs < options.min_pairs) {
    result.refusal = "too few pairs: " + std::to_string(q.pairs) + " (need " +
                     std::to_string(options.min_pairs) + ")";
    return result;
  }
  q.spread_m = minorSpread(floor);
  if (q.spread_m < options.min_spread_m) {
    result.refusal = "floor points nearly on a line: spread " + fixed(q.spread_m, 3) +
                     " m across the motion (need " + fixed(options.min_spread_m, 3) +
                     " m; straight-line motion, drive a curve under the camera)";
    return result;
  }

  // RANSAC for the inliers (OpenCV's generator is seeded, so this is deterministic).
  std::vector<cv::Point2d> src, dst;
  for (std::size_t i = 0; i < floor.size(); ++i) {
    src.emplace_back(floor[i].x(), floor[i].y());
    dst.emplace_back(pixel[i].x(), pixel[i].y());
  }
  std::vector<unsigned char> mask;
  const cv::Mat hcv =
      cv::findHomography(src, dst, cv::RANSAC, options.ransac_threshold_px, mask, 2000, 0.999);
  if (hcv.empty()) {
    result.refusal = "no homography fits the pairs";
    return result;
  }
  std::vector<Eigen::Vector2d> in_floor, in_pixel;
  for (std::size_t i = 0; i < mask.size(); ++i) {
    if (mask[i] == 0) continue;
    in_floor.push_back(floor[i]);
    in_pixel.push_back(pixel[i]);
  }
  q.inliers = static_cast<int>(in_floor.size());
  if (q.inliers < options.min_inlier_fraction * q.pairs || q.inliers < 8) {
    result.refusal = "too few inliers: " + std::to_string(q.inliers) + " of " +
                     std::to_string(q.pairs) + " (need " +
                     fixed(100 * options.min_inlier_fraction, 0) + " %)";
    return result;
  }
  // Gauss-Newton on Hn's 8 free entries, pixel residuals of the inliers; the inliers are then
  // taken again with the refined homography (RANSAC's own model is rough at the image's edges)
  // and the refinement repeated until they settle.
  FloorHomography out;
  Eigen::Matrix3d h_current;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) h_current(r, c) = hcv.at<double>(r, c);
  Eigen::Matrix<double, 8, 8> jtj;
  double sse = 0;
  for (int round = 0; round < 4; ++round) {
    out.floor_norm = normalisation(in_floor);
    out.pixel_norm = normalisation(in_pixel);
    out.hn = out.pixel_norm * h_current * out.floor_norm.inverse();
    if (!(std::abs(out.hn(2, 2)) > 1e-12)) {
      result.refusal = "degenerate homography (the floor points' centre maps to infinity)";
      return result;
    }
    out.hn /= out.hn(2, 2);
    refine(out, in_floor, in_pixel, jtj, sse);
    h_current = out.pixel_norm.inverse() * out.hn * out.floor_norm;
    std::vector<Eigen::Vector2d> next_floor, next_pixel;
    for (std::size_t i = 0; i < floor.size(); ++i) {
      const Eigen::Vector3d qh = h_current * floor[i].homogeneous();
      if (!(qh.z() > 0)) continue;
      if ((qh.head<2>() / qh.z() - pixel[i]).norm() > options.ransac_threshold_px) continue;
      next_floor.push_back(floor[i]);
      next_pixel.push_back(pixel[i]);
    }
    if (next_floor.size() < 8 || next_floor == in_floor) break;
    in_floor = std::move(next_floor);
    in_pixel = std::move(next_pixel);
    if (round == 3) refine(out, in_floor, in_pixel, jtj, sse);
  }
  q.inliers = static_cast<int>(in_floor.size());
  {
    std::vector<cv::Point2f> px;
    for (const auto& p : in_pixel) px.emplace_back(float(p.x()), float(p.y()));
    std::vector<cv::Point2f> hull;
    cv::convexHull(px, hull);
    q.coverage = cv::contourArea(hull) / (double(image_width) * double(image_height));
  }
  if (q.coverage < options.min_coverage) {
    result.refusal = "the sightings cover " + fixed(100 * q.coverage, 1) +
                     " % of the image (need " + fixed(100 * options.min_coverage, 1) + " %)";
    return result;
  }
  out.h = out.pixel_norm.inverse() * out.hn * out.floor_norm;
  out.h /= out.h(2, 2);
  const int n = q.inliers;
  q.rms_px = std::sqrt(sse / n);
  if (q.rms_px > options.max_rms_px) {
    result.refusal = "reprojection RMS " + fixed(q.rms_px, 2) + " px (at most " +
                     fixed(options.max_rms_px, 2) + " px accepted)";
    return result;
  }
  {
    std::vector<Eigen::Vector2d> pn(in_pixel.size());
    std::vector<Eigen::Vector2d> fn(in_floor.size());
    for (std::size_t i = 0; i < in_pixel.size(); ++i) {
      pn[i] = apply(out.pixel_norm, in_pixel[i]);
      fn[i] = apply(out.floor_norm, in_floor[i]);
    }
    q.condition = dltCondition(fn, pn);
  }
  if (!(q.condition <= options.max_condition)) {
    result.refusal = "ill-conditioned: condition number " + fixed(q.condition, 0) + " (at most " +
                     fixed(options.max_condition, 0) + ")";
    return result;
  }
  // Per-axis noise: the claimed one, or the residual's when that is larger (2n residuals, 8
  // parameters).
  const double sigma2 = std::max(pixel_std * pixel_std, sse / std::max(1, 2 * n - 8));
  out.covariance = sigma2 * jtj.ldlt().solve(Eigen::Matrix<double, 8, 8>::Identity());
  if (options.anchor_std_m > 0 || options.anchor_std_rad > 0) {
    // The floor points' frame is off by one rigid motion G (shift t, rotation a about their
    // centroid, the origin of the normalised floor): the camera then fits H G⁻¹ instead of H,
    // whatever the number of points. First order: Hn moves along d(Hn G)/d(t, a).
    const double scale = out.floor_norm(0, 0);  // a similarity: equal scales
    const auto params = [&](double tx, double ty, double a) {
      Eigen::Matrix3d g;
      g << std::cos(a), -std::sin(a), scale * tx, std::sin(a), std::cos(a), scale * ty, 0, 0, 1;
      Eigen::Matrix3d m = out.hn * g;
      m /= m(2, 2);
      Eigen::Matrix<double, 8, 1> v;
      for (int k = 0; k < 8; ++k) v(k) = m(k / 3, k % 3);
      return v;
    };
    const double e = 1e-6;
    Eigen::Matrix<double, 8, 3> j;
    j.col(0) = (params(e, 0, 0) - params(-e, 0, 0)) / (2 * e);
    j.col(1) = (params(0, e, 0) - params(0, -e, 0)) / (2 * e);
    j.col(2) = (params(0, 0, e) - params(0, 0, -e)) / (2 * e);
    const Eigen::Vector3d var(options.anchor_std_m * options.anchor_std_m,
                              options.anchor_std_m * options.anchor_std_m,
                              options.anchor_std_rad * options.anchor_std_rad);
    out.covariance += j * var.asDiagonal() * j.transpose();
  }
  out.quality = q;
  result.homography = out;
  return result;
}

}  // namespace tessera::camera_network
