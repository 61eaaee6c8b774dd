// Local bundle adjustment over the newest keyframes (Ceres, Huber loss; see the header).
#include <tessera/visual_slam/local_bundle_adjustment.hpp>

#include <tessera/visual_slam/tracker.hpp>

#include "rotation_vector.hpp"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <unordered_map>

namespace tessera::visual_slam {

namespace {

// One observation: pose = camera_from_world as (rotation vector, translation), point in the
// world [m]; residuals in pixels (reprojection u, v and, with a depth, disparity).
struct ObservationCost {
  double u, v, disparity, fxb;  // disparity = fx b / z measured; fxb = 0: no depth residual
  double fx, fy, cx, cy;
  double weight;  // of the reprojection residuals: 1 / the keypoint's pyramid scale

  template <typename T>
  bool operator()(const T* pose, const T* point, T* residual) const {
    T c[3];
    ceres::AngleAxisRotatePoint(pose, point, c);
    c[0] += pose[3];
    c[1] += pose[4];
    c[2] += pose[5];
    if (c[2] < T(1e-3)) return false;  // behind the camera: this step is rejected
    residual[0] = T(weight) * (T(fx) * c[0] / c[2] + T(cx) - T(u));
    residual[1] = T(weight) * (T(fy) * c[1] / c[2] + T(cy) - T(v));
    residual[2] = fxb > 0 ? T(fxb) / c[2] - T(disparity) : T(0);
    return true;
  }
};

// A keypoint found on pyramid level L is located to about scale^L pixels of level 0 (ORB's
// 1.2 between levels; SIFT's packed octaves are taken as level 0).
double pyramidWeight(int octave) {
  return octave > 0 && octave < 16 ? std::pow(1.2, -octave) : 1.0;
}

std::array<double, 6> toParams(const Eigen::Isometry3d& camera_from_world) {
  std::array<double, 6> p{};
  detail::toRvecTvec(camera_from_world, p.data());
  return p;
}

}  // namespace

void LocalBundleAdjustmentOptions::validate() const {
  const auto bad = [](const std::string& what) {
    throw std::invalid_argument("local bundle adjustment: " + what);
  };
  if (keyframes < 0) bad("local_ba_keyframes must be >= 0");
  if (fixed_keyframes < 0) bad("local_ba_fixed_keyframes must be >= 0");
  if (iterations < 1) bad("local_ba_iterations must be >= 1");
  if (!(huber_delta > 0) || !std::isfinite(huber_delta)) bad("local_ba_huber must be > 0");
  if (!(depth_baseline >= 0) || !std::isfinite(depth_baseline))
    bad("local_ba_depth_baseline must be >= 0");
}

LocalBundleAdjustmentStats adjustLocalWindow(std::vector<Keyframe>& keyframes,
                                             const PinholeCamera& camera,
                                             const LocalBundleAdjustmentOptions& options) {
  LocalBundleAdjustmentStats stats;
  const std::size_t n = keyframes.size();
  if (options.keyframes < 1 || n < 2) return stats;
  const std::size_t window = static_cast<std::size_t>(options.keyframes);
  const std::size_t first = n > window ? n - window : 0;
  const std::size_t fixed = static_cast<std::size_t>(options.fixed_keyframes);
  const std::size_t oldest = first > fixed ? first - fixed : 0;

  // The points the window sees, and how many keyframes (window or fixed) see each.
  std::unordered_map<std::int64_t, std::size_t> index;
  std::vector<Eigen::Vector3d> points;
  std::vector<int> seen;
  for (std::size_t k = first; k < n; ++k) {
    const Keyframe& kf = keyframes[k];
    for (std::size_t j = 0; j < kf.point_ids.size(); ++j) {
      const std::int64_t id = kf.point_ids[j];
      if (id < 0 || index.count(id) != 0) continue;
      index.emplace(id, points.size());
      points.push_back(kf.points_world[j]);
      seen.push_back(0);
    }
  }
  for (std::size_t k = oldest; k < n; ++k)
    for (const std::int64_t id : keyframes[k].point_ids)
      if (const auto it = index.find(id); id >= 0 && it != index.end()) ++seen[it->second];

  std::vector<std::array<double, 6>> poses(n - oldest);
  for (std::size_t k = oldest; k < n; ++k)
    poses[k - oldest] = toParams(keyframes[k].camera_to_world.inverse());
  std::vector<bool> used(n - oldest, false);

  // The loss outlives the problem and is ours: a window with no usable observation adds no
  // residual block, and a problem owns only the losses its blocks use.
  const auto huber = std::make_unique<ceres::HuberLoss>(options.huber_delta);
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  ceres::LossFunction* loss = huber.get();
  const double fxb = camera.fx * options.depth_baseline;
  bool any_fixed = false;
  for (std::size_t k = oldest; k < n; ++k) {
    const Keyframe& kf = keyframes[k];
    for (std::size_t j = 0; j < kf.point_ids.size(); ++j) {
      const std::int64_t id = kf.point_ids[j];
      if (id < 0) continue;
      const auto it = index.find(id);
      if (it == index.end() || seen[it->second] < 2) continue;
      const double z = kf.points_camera[j].z();
      ObservationCost cost{kf.keypoints[j].pt.x,
                           kf.keypoints[j].pt.y,
                           z > 0 ? fxb / z : 0.0,
                           z > 0 ? fxb : 0.0,
                           camera.fx,
                           camera.fy,
                           camera.cx,
                           camera.cy,
                           pyramidWeight(kf.keypoints[j].octave)};
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<ObservationCost, 3, 6, 3>(new ObservationCost(cost)),
          loss, poses[k - oldest].data(), points[it->second].data());
      used[k - oldest] = true;
      ++stats.observations;
      if (k < first) any_fixed = true;
    }
  }
  if (stats.observations == 0) return stats;
  for (std::size_t k = oldest; k < n; ++k) {
    if (!used[k - oldest]) continue;
    if (k < first) {
      problem.SetParameterBlockConstant(poses[k - oldest].data());
      ++stats.fixed_keyframes;
    } else {
      ++stats.adjusted_keyframes;
    }
  }
  // Without older keyframes the gauge is free: hold the oldest keyframe of the window.
  if (!any_fixed) {
    for (std::size_t k = first; k < n; ++k) {
      if (!used[k - oldest]) continue;
      problem.SetParameterBlockConstant(poses[k - oldest].data());
      --stats.adjusted_keyframes;
      ++stats.fixed_keyframes;
      break;
    }
  }
  if (stats.adjusted_keyframes == 0) return stats;

  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_SCHUR;
  so.max_num_iterations = options.iterations;
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  stats.initial_cost = summary.initial_cost;
  stats.final_cost = summary.final_cost;
  stats.ran = true;
  for (const int s : seen)
    if (s >= 2) ++stats.points;
  if (!summary.IsSolutionUsable() || !(summary.final_cost <= summary.initial_cost)) return stats;

  for (std::size_t k = first; k < n; ++k)
    keyframes[k].camera_to_world = detail::fromRvecTvec(poses[k - oldest].data()).inverse();
  for (std::size_t k = oldest; k < n; ++k) {
    Keyframe& kf = keyframes[k];
    for (std::size_t j = 0; j < kf.point_ids.size(); ++j) {
      const auto it = index.find(kf.point_ids[j]);
      if (kf.point_ids[j] >= 0 && it != index.end() && seen[it->second] >= 2)
        kf.points_world[j] = points[it->second];
    }
  }
  return stats;
}

}  // namespace tessera::visual_slam
