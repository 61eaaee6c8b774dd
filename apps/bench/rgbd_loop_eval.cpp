// Loop closure beside the tracker in `tessera bench rgbd`: detection, ground-truth checks, the
// keyframe graph and its ATE (see the header).
#include "rgbd_loop_eval.hpp"

#include <tessera/evaluation/loop_metrics.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/visual_slam/keyframe_graph.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace tessera::app {
namespace {

namespace vs = tessera::visual_slam;

double keyframeAte(const std::vector<std::pair<double, Eigen::Isometry3d>>& estimate,
                   const std::vector<std::pair<double, Eigen::Isometry3d>>& truth) {
  std::vector<mapping::TumPose> est, ref;
  const auto tum = [](double t, const Eigen::Isometry3d& T) {
    return mapping::TumPose{static_cast<std::int64_t>(std::llround(t * 1e9)), T.translation(),
                            Eigen::Quaterniond(T.rotation())};
  };
  for (const auto& [t, T] : estimate) est.push_back(tum(t, T));
  for (const auto& [t, T] : truth) ref.push_back(tum(t, T));
  if (ref.size() < 3) return 0;
  return evaluation::computeAte(est, ref).translation.rmse;
}

}  // namespace

LoopEvaluation::LoopEvaluation(const vs::LoopDetectorOptions& options,
                               const std::string& vocabulary_path, const vs::PinholeCamera& camera,
                               double max_error_m, double max_error_deg, double min_overlap)
    : options_(options),
      camera_(camera),
      max_error_m_(max_error_m),
      max_error_deg_(max_error_deg),
      min_overlap_(min_overlap) {
  std::shared_ptr<const vs::Vocabulary> vocabulary;
  try {
    if (!vocabulary_path.empty())
      vocabulary = std::make_shared<const vs::Vocabulary>(vs::Vocabulary::load(vocabulary_path));
    detector_ = std::make_unique<vs::LoopDetector>(options_, vocabulary);
  } catch (const std::exception& e) {
    throw ConfigError(std::string("bench rgbd: loops: ") + e.what());
  }
  f_.vocabulary = vocabulary ? "file" : "bootstrap";
}

void LoopEvaluation::addKeyframe(const vs::Keyframe& keyframe, int inliers,
                                 const std::optional<Eigen::Isometry3d>& truth) {
  const std::size_t id = entries_.size();
  Entry e;
  e.estimate = keyframe.camera_to_world;
  e.has_truth = truth.has_value();
  if (truth) e.truth = *truth;
  e.timestamp = keyframe.timestamp;
  e.points = keyframe.points_camera;
  entries_.push_back(std::move(e));
  inliers_.push_back(inliers);

  vs::LoopKeyframe k;
  k.id = static_cast<std::int64_t>(id);
  k.camera = camera_;
  for (const auto& kp : keyframe.keypoints) k.view.pixels.emplace_back(kp.pt.x, kp.pt.y);
  k.view.points = keyframe.points_camera;
  k.view.descriptors = keyframe.descriptors;
  const auto t0 = std::chrono::steady_clock::now();
  const auto queries = detector_->add(std::move(k));
  ms_ += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  for (const auto& q : queries) {
    if (!q.accepted()) continue;
    loops_.push_back({static_cast<std::size_t>(*q.candidate), static_cast<std::size_t>(q.query),
                      q.verification->candidate_from_query, q.verification->covariance});
  }
}

LoopEvalFigures LoopEvaluation::finish() {
  const auto& s = detector_->stats();
  f_.keyframes = entries_.size();
  f_.queries = s.queries;
  f_.candidates = s.candidates;
  f_.rejected_by = s.rejected_by;
  f_.accepted = loops_.size();
  f_.ms_per_keyframe = entries_.empty() ? 0 : ms_ / static_cast<double>(entries_.size());

  // Each loop against the true relative pose of its keyframes (evaluation::checkLoops, the check
  // `tessera eval loops` makes); a loop whose keyframes lack a true pose counts as false here.
  const auto ns = [](double t) { return static_cast<std::int64_t>(std::llround(t * 1e9)); };
  std::vector<evaluation::RelativeMeasurement> measured;
  for (const auto& l : loops_)
    measured.push_back({ns(entries_[l.from].timestamp), ns(entries_[l.to].timestamp),
                        Pose3::fromIsometry(l.relative)});
  std::vector<mapping::TumPose> reference;
  for (const auto& e : entries_)
    if (e.has_truth)
      reference.push_back(
          {ns(e.timestamp), e.truth.translation(), Eigen::Quaterniond(e.truth.rotation())});
  evaluation::LoopCheckOptions check;
  check.max_error_m = max_error_m_;
  check.max_error_deg = max_error_deg_;
  check.max_difference_s = 1e-6;  // keyframe stamps are the reference's own
  const evaluation::LoopCheckResult checked = checkLoops(measured, reference, check);
  f_.false_loops = checked.false_loops + (checked.loops - checked.checked);
  f_.worst_true_error_m = checked.worst_true_m;
  std::vector<char> detected(entries_.size(), 0);
  for (std::size_t i = 0; i < loops_.size(); ++i) {
    const auto& l = loops_[i];
    const bool is_false = std::find(checked.false_indices.begin(), checked.false_indices.end(),
                                    i) != checked.false_indices.end();
    if (!is_false && entries_[l.from].has_truth && entries_[l.to].has_truth) detected[l.to] = 1;
  }
  // Ground-truth revisits: enough of keyframe j's points fall in an old keyframe's image.
  const auto gap = static_cast<std::size_t>(options_.database.recent_excluded);
  for (std::size_t j = 0; j < entries_.size(); ++j) {
    if (!entries_[j].has_truth) continue;
    bool revisit = false;
    for (std::size_t i = 0; i + gap < j && !revisit; ++i) {
      if (!entries_[i].has_truth) continue;
      const Eigen::Isometry3d i_from_j = entries_[i].truth.inverse() * entries_[j].truth;
      std::size_t in = 0, valid = 0;
      for (const auto& p : entries_[j].points) {
        if (!p.allFinite()) continue;
        ++valid;
        const Eigen::Vector3d q = i_from_j * p;
        if (q.z() > 0.3 && q.z() < 6 && camera_.inside(camera_.project(q))) ++in;
      }
      revisit = valid > 0 && static_cast<double>(in) >= min_overlap_ * static_cast<double>(valid);
    }
    if (revisit) {
      ++f_.revisits;
      if (detected[j]) ++f_.true_detected;
    }
  }

  std::vector<std::pair<double, Eigen::Isometry3d>> est, ref;
  for (const auto& e : entries_) {
    est.emplace_back(e.timestamp, e.estimate);
    if (e.has_truth) ref.emplace_back(e.timestamp, e.truth);
  }
  f_.keyframe_ate_m = keyframeAte(est, ref);
  if (!loops_.empty()) {
    vs::KeyframeGraph graph(vs::KeyframeGraphOptions{});
    for (std::size_t i = 0; i < entries_.size(); ++i)
      graph.addKeyframe(static_cast<std::int64_t>(i), Pose3::fromIsometry(entries_[i].estimate),
                        inliers_[i]);
    for (const auto& l : loops_)
      graph.addLoop({static_cast<std::int64_t>(l.from), static_cast<std::int64_t>(l.to),
                     Pose3::fromIsometry(l.relative), l.covariance});
    graph.optimize();
    est.clear();
    for (const auto& [id, p] : graph.poses()) {
      const Entry& e = entries_[static_cast<std::size_t>(id)];
      f_.corrections.push_back({static_cast<std::int64_t>(std::llround(e.timestamp * 1e9)),
                                Pose3::fromIsometry(e.estimate), p});
      est.emplace_back(e.timestamp, p.isometry());
    }
    f_.keyframe_ate_loops_m = keyframeAte(est, ref);
  } else {
    f_.keyframe_ate_loops_m = f_.keyframe_ate_m;
  }
  return f_;
}

}  // namespace tessera::app
