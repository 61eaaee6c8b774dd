// checkLoops: loop closures against a reference trajectory.
#include <tessera/evaluation/loop_metrics.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>

namespace tessera::evaluation {
namespace {

/// The reference pose nearest to t, if within max_difference_s.
std::optional<Pose3> nearest(const std::vector<mapping::TumPose>& sorted, std::int64_t t,
                             double max_difference_s) {
  const auto it =
      std::lower_bound(sorted.begin(), sorted.end(), t,
                       [](const mapping::TumPose& p, std::int64_t x) { return p.stamp_ns < x; });
  const mapping::TumPose* best = nullptr;
  if (it != sorted.end()) best = &*it;
  if (it != sorted.begin() &&
      (!best || std::llabs(std::prev(it)->stamp_ns - t) < std::llabs(best->stamp_ns - t)))
    best = &*std::prev(it);
  if (!best || std::llabs(best->stamp_ns - t) > std::llround(max_difference_s * 1e9))
    return std::nullopt;
  return Pose3{best->position, best->orientation.normalized()};
}

}  // namespace

LoopCheckResult checkLoops(const std::vector<RelativeMeasurement>& loops,
                           const std::vector<mapping::TumPose>& reference,
                           const LoopCheckOptions& options) {
  std::vector<mapping::TumPose> sorted = reference;
  std::sort(sorted.begin(), sorted.end(),
            [](const auto& a, const auto& b) { return a.stamp_ns < b.stamp_ns; });
  LoopCheckResult out;
  out.loops = loops.size();
  std::vector<double> translation, rotation;
  for (std::size_t i = 0; i < loops.size(); ++i) {
    const auto a = nearest(sorted, loops[i].from_ns, options.max_difference_s);
    const auto b = nearest(sorted, loops[i].to_ns, options.max_difference_s);
    if (!a || !b) continue;
    ++out.checked;
    const Pose3 truth = a->inverse() * *b;
    const Pose3 error = truth.inverse() * loops[i].relative;
    const double t = error.t.norm();
    const double r =
        2 * std::atan2(error.q.vec().norm(), std::abs(error.q.w())) * 180 / std::numbers::pi;
    translation.push_back(t);
    rotation.push_back(r);
    if (t > options.max_error_m || r > options.max_error_deg || !std::isfinite(t + r)) {
      ++out.false_loops;
      out.false_indices.push_back(i);
    } else {
      out.worst_true_m = std::max(out.worst_true_m, t);
    }
  }
  out.translation = summarize(translation);
  out.rotation_deg = summarize(rotation);
  return out;
}

}  // namespace tessera::evaluation
