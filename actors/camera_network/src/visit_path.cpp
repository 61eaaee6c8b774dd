// A calibration visit's path corrected with the camera's pixels: see visit_path.hpp.
#include <tessera/camera_network/visit_path.hpp>

#include <tessera/camera_network/camera_localization.hpp>

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>

namespace tessera::camera_network {

ConfigCheck VisitPathOptions::check() const {
  ConfigCheck c;
  c.positive("segment_s", segment_s)
      .nonNegative("distance_var_per_m", distance_var_per_m)
      .nonNegative("heading_var_per_rad", heading_var_per_rad)
      .nonNegative("heading_var_per_m", heading_var_per_m)
      .require(max_iterations >= 1, "max_iterations", "must be >= 1", max_iterations);
  return c;
}

namespace {

// A segment whose prior variance is below this is held where it is (the robot stood still).
constexpr double kMinVariance = 1e-14;

/// The visit's odometry increments and how each segment's corrections spread over them.
struct Increments {
  std::vector<Pose2> delta;                       ///< poses[k]⁻¹ ⊕ poses[k+1]
  std::vector<int> segment;                       ///< of increment k
  std::vector<double> heading_w;                  ///< share of its segment's heading correction
  std::vector<double> scale_per_m;                ///< 1 / its segment's distance [1/m] (0: none)
  std::vector<double> heading_var, distance_var;  ///< per segment
};

Increments increments(const std::vector<std::int64_t>& stamps, const std::vector<Pose2>& poses,
                      const VisitPathOptions& o) {
  Increments in;
  const std::size_t n = poses.size();
  int segments = 0;
  for (std::size_t k = 0; k + 1 < n; ++k) {
    in.delta.push_back(between(poses[k], poses[k + 1]));
    const int s = static_cast<int>(1e-9 * double(stamps[k] - stamps.front()) / o.segment_s);
    in.segment.push_back(s);
    segments = std::max(segments, s + 1);
  }
  in.heading_var.assign(segments, 0.0);
  in.distance_var.assign(segments, 0.0);
  std::vector<double> length(segments, 0.0);
  std::vector<double> v(in.delta.size());
  for (std::size_t k = 0; k < in.delta.size(); ++k) {
    const double len = in.delta[k].translation().norm();
    v[k] = o.heading_var_per_rad * std::abs(in.delta[k].theta) + o.heading_var_per_m * len;
    in.heading_var[in.segment[k]] += v[k];
    length[in.segment[k]] += len;
  }
  for (int s = 0; s < segments; ++s) in.distance_var[s] = o.distance_var_per_m * length[s];
  for (std::size_t k = 0; k < in.delta.size(); ++k) {
    const int s = in.segment[k];
    in.heading_w.push_back(in.heading_var[s] > 0 ? v[k] / in.heading_var[s] : 0.0);
    in.scale_per_m.push_back(length[s] > 1e-9 ? 1.0 / length[s] : 0.0);
  }
  return in;
}

/// The path with corrections x = [heading per segment, distance per segment] applied.
std::vector<Pose2> correctedPath(const Pose2& start, const Increments& in, const Eigen::VectorXd& x,
                                 int segments) {
  std::vector<Pose2> path{start};
  path.reserve(in.delta.size() + 1);
  for (std::size_t k = 0; k < in.delta.size(); ++k) {
    const int s = in.segment[k];
    const Pose2& d = in.delta[k];
    const double scale = 1.0 + x(segments + s) * in.scale_per_m[k];
    path.push_back(path.back() * Pose2(scale * d.x, scale * d.y, d.theta + x(s) * in.heading_w[k]));
  }
  return path;
}

}  // namespace

VisitPathResult refineVisitPath(const std::vector<std::int64_t>& stamps_ns,
                                const std::vector<Pose2>& poses, const std::vector<Pose2>& anchor,
                                const std::vector<Eigen::Vector2d>& pixels,
                                const Eigen::Vector2d& marker, const FloorHomography& initial,
                                double pixel_std, double inlier_px,
                                const VisitPathOptions& options) {
  options.check().throwIfBad("visit path");
  VisitPathResult result;
  const std::size_t n = poses.size();
  if (n < 2 || stamps_ns.size() != n || pixels.size() != n) {
    result.refusal = "need at least 2 poses with one stamp and one pixel each";
    return result;
  }
  if (!anchor.empty() && anchor.size() != n) {
    result.refusal = "need one anchor pose per pose (or none)";
    return result;
  }
  if (!(pixel_std > 0) || !std::isfinite(pixel_std) || !(inlier_px > 0) || !marker.allFinite() ||
      !initial.hn.allFinite()) {
    result.refusal = "pixel_std, inlier_px, the marker and the homography must be finite (> 0)";
    return result;
  }
  for (std::size_t k = 0; k < n; ++k) {
    if (!poses[k].isFinite() || !pixels[k].allFinite() ||
        (!anchor.empty() && !anchor[k].isFinite())) {
      result.refusal = "non-finite pose or pixel at sighting " + std::to_string(k);
      return result;
    }
    if (k > 0 && stamps_ns[k] < stamps_ns[k - 1]) {
      result.refusal = "stamps go back in time at sighting " + std::to_string(k);
      return result;
    }
  }
  const Increments in = increments(stamps_ns, poses, options);
  const int segments = static_cast<int>(in.heading_var.size());
  result.segments = segments;

  // Pixel of the marker at a robot pose through normalised Hn (entries of order 1, so that a
  // numeric derivative step suits all of them).
  const Eigen::Matrix3d pixel_denorm = initial.pixel_norm.inverse();
  const auto project = [&](const Eigen::Matrix3d& hn, const Pose2& robot, Eigen::Vector2d& px) {
    const Eigen::Vector3d q = hn * (initial.floor_norm * (robot * marker).homogeneous());
    if (!(q.z() > 0)) return false;
    const Eigen::Vector3d p = pixel_denorm * Eigen::Vector3d(q.x() / q.z(), q.y() / q.z(), 1.0);
    px = p.head<2>() / p.z();
    return true;
  };
  std::vector<std::size_t> inliers;
  double sse_before = 0;
  for (std::size_t k = 0; k < n; ++k) {
    Eigen::Vector2d px;
    if (!project(initial.hn, poses[k], px)) continue;
    const double e = (px - pixels[k]).squaredNorm();
    if (e > inlier_px * inlier_px) continue;
    inliers.push_back(k);
    sse_before += e;
  }
  result.inliers = static_cast<int>(inliers.size());
  if (inliers.size() < 8 || 2 * inliers.size() < 8 + 2 * std::size_t(segments)) {
    result.refusal = "too few inlier pixels (" + std::to_string(inliers.size()) + ") for " +
                     std::to_string(segments) + " segments";
    return result;
  }
  result.rms_before_px = std::sqrt(sse_before / double(inliers.size()));

  // Parameters: Hn's 8 free entries, then the heading and the distance corrections.
  const int np = 8 + 2 * segments;
  const int nr = 2 * static_cast<int>(inliers.size()) + 2 * segments;
  std::vector<double> prior_std(2 * segments);
  for (int s = 0; s < segments; ++s) {
    prior_std[s] = std::sqrt(std::max(in.heading_var[s], kMinVariance));
    prior_std[segments + s] = std::sqrt(std::max(in.distance_var[s], kMinVariance));
  }
  const auto residuals = [&](const Eigen::VectorXd& x, Eigen::VectorXd& r) {
    Eigen::Matrix3d hn = initial.hn;
    for (int k = 0; k < 8; ++k) hn(k / 3, k % 3) = x(k);
    const Eigen::VectorXd corr = x.tail(2 * segments);
    const auto path = correctedPath(poses.front(), in, corr, segments);
    r.resize(nr);
    for (std::size_t i = 0; i < inliers.size(); ++i) {
      Eigen::Vector2d px;
      if (!project(hn, path[inliers[i]], px)) return false;
      r.segment<2>(2 * static_cast<Eigen::Index>(i)) = (px - pixels[inliers[i]]) / pixel_std;
    }
    for (int j = 0; j < 2 * segments; ++j)
      r(2 * static_cast<Eigen::Index>(inliers.size()) + j) = corr(j) / prior_std[j];
    return true;
  };

  Eigen::VectorXd x = Eigen::VectorXd::Zero(np);
  for (int k = 0; k < 8; ++k) x(k) = initial.hn(k / 3, k % 3);
  Eigen::VectorXd r;
  if (!residuals(x, r)) {
    result.refusal = "the initial homography puts a sighting behind the camera";
    return result;
  }
  double cost = r.squaredNorm();
  double lambda = 1e-3;
  Eigen::MatrixXd jac(nr, np);
  Eigen::VectorXd rp, rm;
  for (int it = 0; it < options.max_iterations; ++it) {
    bool ok = true;
    for (int p = 0; p < np && ok; ++p) {
      // Central differences; path steps scaled by their prior (a fraction of a sigma).
      const double step = p < 8 ? 1e-6 * std::max(1.0, std::abs(x(p))) : 1e-3 * prior_std[p - 8];
      Eigen::VectorXd xp = x, xm = x;
      xp(p) += step;
      xm(p) -= step;
      ok = residuals(xp, rp) && residuals(xm, rm);
      if (ok) jac.col(p) = (rp - rm) / (2 * step);
    }
    if (!ok) break;
    const Eigen::MatrixXd jtj = jac.transpose() * jac;
    const Eigen::VectorXd jtr = jac.transpose() * r;
    bool improved = false;
    for (int tries = 0; tries < 8 && !improved; ++tries) {
      Eigen::MatrixXd a = jtj;
      a.diagonal() += lambda * jtj.diagonal().cwiseMax(1e-12);
      const Eigen::VectorXd dx = -a.ldlt().solve(jtr);
      const Eigen::VectorXd trial = x + dx;
      Eigen::VectorXd rt;
      if (dx.allFinite() && residuals(trial, rt) && rt.squaredNorm() < cost) {
        const bool small = cost - rt.squaredNorm() < 1e-10 * (1 + cost);
        x = trial;
        r = rt;
        cost = r.squaredNorm();
        lambda = std::max(1e-9, lambda * 0.3);
        improved = true;
        if (small) it = options.max_iterations;
      } else {
        lambda *= 10;
      }
    }
    if (!improved) break;
  }

  const Eigen::VectorXd corr = x.tail(2 * segments);
  const auto path = correctedPath(poses.front(), in, corr, segments);
  double sse_after = 0;
  for (std::size_t i = 0; i < inliers.size(); ++i)
    sse_after += r.segment<2>(2 * static_cast<Eigen::Index>(i)).squaredNorm();
  result.rms_after_px = pixel_std * std::sqrt(sse_after / double(inliers.size()));
  result.prior_chi2 = r.tail(2 * segments).squaredNorm();
  for (std::size_t k = 0; k < n; ++k) {
    const double d = std::abs(angleDiff(path[k].theta, poses[k].theta));
    result.max_heading_rad = std::max(result.max_heading_rad, d);
  }
  // Where the SLAM put the visit: the rigid motion that fits the corrected positions onto the
  // anchor's.
  const std::vector<Pose2>& onto = anchor.empty() ? poses : anchor;
  std::vector<Eigen::Vector2d> from, to;
  for (std::size_t k = 0; k < n; ++k) {
    from.push_back(path[k].translation());
    to.push_back(onto[k].translation());
  }
  const Pose2 place = closedFormRigidFit(from, to);
  result.poses.reserve(n);
  for (const auto& p : path) result.poses.push_back(place * p);
  return result;
}

}  // namespace tessera::camera_network
