// KeyframeGraph: odometry and loop edges between keyframes, optimised with the pose_graph core.
#include <tessera/visual_slam/keyframe_graph.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <stdexcept>

namespace tessera::visual_slam {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

bool finite(const Pose3& p) {
  return p.t.allFinite() && p.q.coeffs().allFinite() && p.q.norm() > 1e-9;
}

/// The graph's rotation error is the quaternion's imaginary part, half the rotation vector: its
/// information is that of the rotation vector with the rotation block scaled by 2 on each side.
Matrix6d quaternionErrorInformation(const Matrix6d& rotation_vector_information) {
  Eigen::Matrix<double, 6, 1> d;
  d << 1, 1, 1, 2, 2, 2;
  return d.asDiagonal() * rotation_vector_information * d.asDiagonal();
}

}  // namespace

void KeyframeGraphOptions::validate() const {
  const auto positive = [](double v) { return std::isfinite(v) && v > 0; };
  if (!positive(odometry_sigma_translation))
    throw std::invalid_argument("odometry_sigma_translation must be > 0");
  if (!positive(odometry_sigma_rotation))
    throw std::invalid_argument("odometry_sigma_rotation must be > 0");
  if (reference_inliers < 1) throw std::invalid_argument("reference_inliers must be >= 1");
  if (!positive(trimming.radius_m)) throw std::invalid_argument("trimming.radius_m must be > 0");
  if (!positive(trimming.angle_rad)) throw std::invalid_argument("trimming.angle_rad must be > 0");
  if (trimming.min_age < 1) throw std::invalid_argument("trimming.min_age must be >= 1");
  if (const std::string e = pose_graph::optionsError(optimizer); !e.empty())
    throw std::invalid_argument("optimizer." + e);
}

KeyframeGraph::KeyframeGraph(const KeyframeGraphOptions& options) : options_(options) {
  options_.validate();
}

bool KeyframeGraph::addKeyframe(std::int64_t id, const Pose3& tracker_pose, int inliers) {
  error_.clear();
  if (!finite(tracker_pose)) {
    error_ = "keyframe " + std::to_string(id) + ": pose is not finite";
    return false;
  }
  if (graph_.contains(id)) {
    error_ = "keyframe " + std::to_string(id) + " was added before";
    return false;
  }
  const Pose3 pose{tracker_pose.t, tracker_pose.q.normalized()};
  if (!last_id_) {
    graph_.addNode(id, pose, /*is_fixed=*/true);
  } else {
    const int prev = graph_.index(*last_id_);
    const Pose3 relative = last_tracker_pose_.inverse() * pose;
    const Pose3 start = graph_.poses[static_cast<std::size_t>(prev)] * relative;
    const int node = graph_.addNode(id, start);
    pose_graph::Edge3D edge;
    edge.from = prev;
    edge.to = node;
    edge.measurement = relative;
    double scale = 1.0;
    if (options_.inlier_weighting && inliers > 0)
      scale = std::clamp(static_cast<double>(inliers) / options_.reference_inliers, 0.1, 10.0);
    Eigen::Matrix<double, 6, 1> info;
    const double it =
        1.0 / (options_.odometry_sigma_translation * options_.odometry_sigma_translation);
    const double ir = 1.0 / (options_.odometry_sigma_rotation * options_.odometry_sigma_rotation);
    info << it, it, it, ir, ir, ir;
    edge.information = quaternionErrorInformation(Matrix6d(info.asDiagonal())) * scale;
    graph_.edges.push_back(edge);
  }
  last_id_ = id;
  last_tracker_pose_ = pose;
  // Loops that waited for this keyframe.
  for (auto it = pending_.begin(); it != pending_.end();) {
    if (graph_.contains(it->from) && graph_.contains(it->to)) {
      insertLoop(*it);
      it = pending_.erase(it);
    } else {
      ++it;
    }
  }
  return true;
}

KeyframeGraph::Outcome KeyframeGraph::addLoop(const LoopConstraint& loop) {
  error_.clear();
  const std::string name = std::to_string(loop.from) + " -> " + std::to_string(loop.to);
  if (loop.from == loop.to) {
    error_ = "loop " + name + " joins a keyframe to itself";
    return Outcome::kRejected;
  }
  if (!finite(loop.relative) || !loop.covariance.allFinite()) {
    error_ = "loop " + name + ": not finite";
    return Outcome::kRejected;
  }
  const Matrix6d sym = 0.5 * (loop.covariance + loop.covariance.transpose());
  if ((sym - loop.covariance).cwiseAbs().maxCoeff() > 1e-9 * (1 + sym.cwiseAbs().maxCoeff()) ||
      Eigen::SelfAdjointEigenSolver<Matrix6d>(sym).eigenvalues().minCoeff() <= 0) {
    error_ = "loop " + name + ": covariance is not symmetric positive definite";
    return Outcome::kRejected;
  }
  for (const std::int64_t end : {loop.from, loop.to}) {
    if (last_id_ && end <= *last_id_ && !graph_.contains(end)) {
      error_ = "loop " + name + ": keyframe " + std::to_string(end) +
               " is no longer in the graph (trimmed or rejected)";
      return Outcome::kRejected;
    }
  }
  if (!graph_.contains(loop.from) || !graph_.contains(loop.to)) {
    pending_.push_back(loop);
    return Outcome::kPending;
  }
  return insertLoop(loop);
}

KeyframeGraph::Outcome KeyframeGraph::insertLoop(const LoopConstraint& loop) {
  pose_graph::Edge3D edge;
  edge.from = graph_.index(loop.from);
  edge.to = graph_.index(loop.to);
  edge.measurement = {loop.relative.t, loop.relative.q.normalized()};
  const Matrix6d sym = 0.5 * (loop.covariance + loop.covariance.transpose());
  edge.information = quaternionErrorInformation(sym.inverse());
  edge.information = 0.5 * (edge.information + edge.information.transpose()).eval();
  edge.robust = true;
  graph_.edges.push_back(edge);
  ++loops_;
  dirty_ = true;
  return Outcome::kAdded;
}

pose_graph::OptimizerSummary KeyframeGraph::optimize() {
  const auto summary = pose_graph::optimize(graph_, options_.optimizer);
  dirty_ = false;
  return summary;
}

std::vector<std::int64_t> KeyframeGraph::trim() {
  std::vector<std::int64_t> out;
  const auto& t = options_.trimming;
  const int n = graph_.size();
  if (!t.enabled || n <= t.min_age + 1) return out;
  // From the newest candidate back to the second keyframe: the keyframes newer than a candidate
  // are decided before it, so a covering keyframe is one that stays.
  std::vector<char> kept(static_cast<std::size_t>(n), 1);
  const double cos_half = std::cos(0.5 * t.angle_rad);
  for (int j = n - 1 - t.min_age; j >= 1; --j) {
    const Pose3& pj = graph_.poses[static_cast<std::size_t>(j)];
    for (int i = j + t.min_age; i < n; ++i) {
      if (!kept[static_cast<std::size_t>(i)]) continue;
      const Pose3& pi = graph_.poses[static_cast<std::size_t>(i)];
      // |<q_i, q_j>| = cos(angle / 2) of the rotation between them.
      if ((pi.t - pj.t).norm() < t.radius_m && std::abs(pi.q.dot(pj.q)) > cos_half) {
        kept[static_cast<std::size_t>(j)] = 0;
        break;
      }
    }
  }
  for (int j = 1; j < n; ++j)
    if (!kept[static_cast<std::size_t>(j)]) out.push_back(graph_.ids[static_cast<std::size_t>(j)]);
  for (const std::int64_t id : out) pose_graph::marginalizeNode(graph_, id);
  trimmed_ += out.size();
  return out;
}

std::map<std::int64_t, Pose3> KeyframeGraph::poses() const {
  std::map<std::int64_t, Pose3> out;
  for (int i = 0; i < graph_.size(); ++i)
    out.emplace(graph_.ids[static_cast<std::size_t>(i)], graph_.poses[static_cast<std::size_t>(i)]);
  return out;
}

double KeyframeGraph::chi2() const {
  return graph_.edges.empty() ? 0.0 : pose_graph::chi2(graph_);
}

std::vector<Pose3> correctFramePoses(const std::vector<std::pair<std::int64_t, Pose3>>& frames,
                                     std::vector<KeyframeCorrection> keyframes) {
  std::sort(keyframes.begin(), keyframes.end(),
            [](const auto& a, const auto& b) { return a.stamp_ns < b.stamp_ns; });
  std::vector<Pose3> out;
  out.reserve(frames.size());
  for (const auto& [stamp, pose] : frames) {
    const auto it = std::upper_bound(keyframes.begin(), keyframes.end(), stamp,
                                     [](std::int64_t t, const auto& k) { return t < k.stamp_ns; });
    if (it == keyframes.begin()) {
      out.push_back(pose);
      continue;
    }
    const KeyframeCorrection& k = *std::prev(it);
    out.push_back(k.optimised * k.tracked.inverse() * pose);
  }
  return out;
}

}  // namespace tessera::visual_slam
