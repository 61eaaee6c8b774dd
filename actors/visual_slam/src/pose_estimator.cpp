// PoseEstimator: RANSAC PnP (OpenCV) with the thesis's iteration count, then a Huber-robust
// motion-only refinement (Ceres) and the inlier re-count (see the header).
#include <tessera/visual_slam/pose_estimator.hpp>

#include "rotation_vector.hpp"

#include <opencv2/calib3d.hpp>

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace tessera::visual_slam {

namespace {

// Reprojection residual of one world point under pose = (rotation vector, translation) of
// camera_from_world, in pixels.
struct ReprojectionCost {
  Eigen::Vector3d point;
  Eigen::Vector2d pixel;
  double fx, fy, cx, cy;

  template <typename T>
  bool operator()(const T* pose, T* residual) const {
    const T p[3] = {T(point.x()), T(point.y()), T(point.z())};
    T c[3];
    ceres::AngleAxisRotatePoint(pose, p, c);
    c[0] += pose[3];
    c[1] += pose[4];
    c[2] += pose[5];
    residual[0] = T(fx) * c[0] / c[2] + T(cx) - T(pixel.x());
    residual[1] = T(fy) * c[1] / c[2] + T(cy) - T(pixel.y());
    return true;
  }
};

// The same with the measured depth as a third residual, in pixels of disparity as a stereo
// camera of baseline b would see it (ORB-SLAM2's RGB-D residual): fx b / z_predicted - fx b / z
// measured, so a depth counts less the farther it is, as its noise grows.
struct ReprojectionDepthCost {
  ReprojectionCost reprojection;
  double disparity;  // fx b / z measured [px]
  double fxb;        // fx b [px m]

  template <typename T>
  bool operator()(const T* pose, T* residual) const {
    reprojection(pose, residual);
    const T p[3] = {T(reprojection.point.x()), T(reprojection.point.y()),
                    T(reprojection.point.z())};
    T c[3];
    ceres::AngleAxisRotatePoint(pose, p, c);
    residual[2] = T(fxb) / (c[2] + pose[5]) - T(disparity);
    return true;
  }
};

using detail::fromRvecTvec;
using detail::toRvecTvec;

int cvFlags(PnpMethod m) {
  switch (m) {
    case PnpMethod::kAp3p:
      return cv::SOLVEPNP_AP3P;
    case PnpMethod::kEpnp:
      return cv::SOLVEPNP_EPNP;
    case PnpMethod::kIterative:
      break;
  }
  return cv::SOLVEPNP_ITERATIVE;
}

}  // namespace

void PoseEstimatorOptions::validate() const {
  const auto bad = [](const std::string& what) {
    throw std::invalid_argument("pose estimator: " + what);
  };
  if (!(confidence > 0 && confidence < 1)) bad("ransac_confidence must be in (0, 1)");
  if (!(min_inlier_ratio > 0 && min_inlier_ratio <= 1))
    bad("ransac_min_inlier_ratio must be in (0, 1]");
  if (max_iterations < 1) bad("ransac_max_iterations must be >= 1");
  if (!(reprojection_error > 0) || !std::isfinite(reprojection_error))
    bad("reprojection_error must be > 0");
  if (min_inliers < 4) bad("pnp_min_inliers must be >= 4");
  if (!(huber_delta > 0) || !std::isfinite(huber_delta)) bad("huber_delta must be > 0");
  if (!(depth_baseline >= 0) || !std::isfinite(depth_baseline)) bad("depth_baseline must be >= 0");
  if (refine_iterations < 1) bad("refine_iterations must be >= 1");
}

int ransacIterations(double p, double w, int m, int cap) {
  const double denom = std::log(1.0 - std::pow(w, m));
  if (!(denom < 0) || !std::isfinite(denom)) return cap;  // w^m underflowed (or w = 1: one try)
  const double k = std::ceil(std::log(1.0 - p) / denom);
  return std::clamp(static_cast<int>(std::min(k, 1e9)), 1, cap);
}

int minimalSample(PnpMethod method) {
  return method == PnpMethod::kIterative || method == PnpMethod::kEpnp ? 5 : 4;
}

PoseEstimator::PoseEstimator(const PoseEstimatorOptions& options, const PinholeCamera& camera)
    : options_(options), camera_(camera) {
  options_.validate();
  camera_.validate();
}

PoseEstimate PoseEstimator::estimate(const std::vector<Eigen::Vector3d>& points,
                                     const std::vector<Eigen::Vector2d>& pixels,
                                     const std::optional<Eigen::Isometry3d>& guess,
                                     const std::vector<double>* depths) const {
  const auto& o = options_;
  PoseEstimate out;
  if (points.size() != pixels.size()) {
    out.failure = "points and pixels differ in count";
    return out;
  }
  // Only finite correspondences enter; `index` maps back to the caller's.
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  std::vector<int> index;
  std::vector<double> depth;  // measured z of each kept correspondence, NaN when none
  if (depths != nullptr && depths->size() != points.size()) {
    out.failure = "depths and points differ in count";
    return out;
  }
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite() || !pixels[i].allFinite()) continue;
    obj.emplace_back(points[i].x(), points[i].y(), points[i].z());
    img.emplace_back(pixels[i].x(), pixels[i].y());
    index.push_back(static_cast<int>(i));
    depth.push_back(depths != nullptr ? (*depths)[i] : std::nan(""));
  }
  const int m = minimalSample(o.method);
  if (static_cast<int>(obj.size()) < std::max(o.min_inliers, m)) {
    out.failure = "too few correspondences (" + std::to_string(obj.size()) + ")";
    return out;
  }

  const cv::Matx33d k(camera_.fx, 0, camera_.cx, 0, camera_.fy, camera_.cy, 0, 0, 1);
  double pose[6] = {0, 0, 0, 0, 0, 0};
  if (guess) toRvecTvec(*guess, pose);
  cv::Vec3d rvec(pose[0], pose[1], pose[2]), tvec(pose[3], pose[4], pose[5]);
  std::vector<int> ransac_inliers;
  out.ransac_iterations = ransacIterations(o.confidence, o.min_inlier_ratio, m, o.max_iterations);
  bool found = false;
  try {
    found = cv::solvePnPRansac(obj, img, k, cv::noArray(), rvec, tvec, guess.has_value(),
                               out.ransac_iterations, static_cast<float>(o.reprojection_error),
                               o.confidence, ransac_inliers, cvFlags(o.method));
  } catch (const cv::Exception& e) {
    out.failure = std::string("solvePnPRansac: ") + e.what();
    return out;
  }
  out.ransac_inliers = static_cast<int>(ransac_inliers.size());
  if (!found || out.ransac_inliers < o.min_inliers) {
    out.failure = "RANSAC found " + std::to_string(out.ransac_inliers) + " inliers";
    return out;
  }
  for (int i = 0; i < 3; ++i) {
    pose[i] = rvec[i];
    pose[3 + i] = tvec[i];
  }
  if (!std::all_of(pose, pose + 6, [](double x) { return std::isfinite(x); })) {
    out.failure = "RANSAC returned a non-finite pose";
    return out;
  }

  // Inliers and squared errors at a pose.
  const auto count = [&](const double* p, std::vector<int>& inl, double& sq) {
    const Eigen::Isometry3d t = fromRvecTvec(p);
    inl.clear();
    sq = 0;
    const double thr2 = o.reprojection_error * o.reprojection_error;
    for (std::size_t i = 0; i < obj.size(); ++i) {
      const Eigen::Vector3d c = t * Eigen::Vector3d(obj[i].x, obj[i].y, obj[i].z);
      if (c.z() <= 0) continue;
      const double e2 = (camera_.project(c) - Eigen::Vector2d(img[i].x, img[i].y)).squaredNorm();
      if (e2 <= thr2) {
        inl.push_back(static_cast<int>(i));
        sq += e2;
      }
    }
  };

  std::vector<int> inliers;
  double sq = 0;
  count(pose, inliers, sq);
  if (o.refine) {
    double refined[6];
    std::copy(pose, pose + 6, refined);
    ceres::Problem::Options popts;
    popts.loss_function_ownership = ceres::TAKE_OWNERSHIP;
    ceres::Problem problem(popts);
    auto* loss = new ceres::HuberLoss(o.huber_delta);
    const double fxb = camera_.fx * o.depth_baseline;
    for (int i : ransac_inliers) {
      const auto u = static_cast<std::size_t>(i);
      const auto& p = obj[u];
      const auto& q = img[u];
      const ReprojectionCost cost{Eigen::Vector3d(p.x, p.y, p.z),
                                  Eigen::Vector2d(q.x, q.y),
                                  camera_.fx,
                                  camera_.fy,
                                  camera_.cx,
                                  camera_.cy};
      if (fxb > 0 && std::isfinite(depth[u]) && depth[u] > 0)
        problem.AddResidualBlock(new ceres::AutoDiffCostFunction<ReprojectionDepthCost, 3, 6>(
                                     new ReprojectionDepthCost{cost, fxb / depth[u], fxb}),
                                 loss, refined);
      else
        problem.AddResidualBlock(
            new ceres::AutoDiffCostFunction<ReprojectionCost, 2, 6>(new ReprojectionCost(cost)),
            loss, refined);
    }
    ceres::Solver::Options sopts;
    sopts.linear_solver_type = ceres::DENSE_QR;
    sopts.max_num_iterations = o.refine_iterations;
    sopts.logging_type = ceres::SILENT;
    sopts.num_threads = 1;
    ceres::Solver::Summary summary;
    ceres::Solve(sopts, &problem, &summary);
    std::vector<int> refined_inliers;
    double refined_sq = 0;
    const bool finite =
        std::all_of(refined, refined + 6, [](double x) { return std::isfinite(x); });
    if (finite) count(refined, refined_inliers, refined_sq);
    // Keep the refinement unless it lost support (a degenerate inlier set can pull it away).
    if (finite && refined_inliers.size() >= inliers.size()) {
      std::copy(refined, refined + 6, pose);
      inliers = std::move(refined_inliers);
      sq = refined_sq;
      double cost = 0;
      ceres::CRSMatrix jac;
      problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, &jac);
      Eigen::Matrix<double, 6, 6> jtj = Eigen::Matrix<double, 6, 6>::Zero();
      for (int r = 0; r < jac.num_rows; ++r) {
        Eigen::Matrix<double, 6, 1> row = Eigen::Matrix<double, 6, 1>::Zero();
        for (int idx = jac.rows[r]; idx < jac.rows[r + 1]; ++idx)
          row[jac.cols[idx]] = jac.values[idx];
        jtj += row * row.transpose();
      }
      const int dof = jac.num_rows - 6;
      const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(jtj);
      if (dof > 0 && ldlt.info() == Eigen::Success && ldlt.isPositive())
        out.covariance = ldlt.solve(Eigen::Matrix<double, 6, 6>::Identity()) * (2 * cost / dof);
    }
  }
  if (static_cast<int>(inliers.size()) < o.min_inliers) {
    out.failure = "only " + std::to_string(inliers.size()) + " inliers at the final pose";
    return out;
  }
  out.ok = true;
  out.camera_from_world = fromRvecTvec(pose);
  out.rms_px = std::sqrt(sq / static_cast<double>(inliers.size()));
  out.inliers.reserve(inliers.size());
  for (int i : inliers) out.inliers.push_back(index[static_cast<std::size_t>(i)]);
  return out;
}

}  // namespace tessera::visual_slam
