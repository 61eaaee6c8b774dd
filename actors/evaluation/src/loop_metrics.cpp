// checkLoops: loop closures against a reference trajectory.
#include <tessera/evaluation/loop_metrics.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>

namespace tessera::evaluation {
namespace {

/// The reference pose nearest to t, if within max_difference_s (`stamps` sorted, as `poses`).
std::optional<Pose3> nearest(const std::vector<mapping::TumPose>& poses,
                             const std::vector<std::int64_t>& stamps, std::int64_t t,
                             double max_difference_s) {
  if (stamps.empty()) return std::nullopt;
  const mapping::TumPose& p = poses[nearestIndex(stamps, t)];
  if (std::llabs(p.stamp_ns - t) > std::llround(max_difference_s * 1e9)) return std::nullopt;
  return Pose3{p.position, p.orientation.normalized()};
}

}  // namespace

LoopCheckResult checkLoops(const std::vector<RelativeMeasurement>& loops,
                           const std::vector<mapping::TumPose>& reference,
                           const LoopCheckOptions& options) {
  std::vector<mapping::TumPose> sorted = reference;
  std::sort(sorted.begin(), sorted.end(),
            [](const auto& a, const auto& b) { return a.stamp_ns < b.stamp_ns; });
  std::vector<std::int64_t> stamps;
  for (const auto& p : sorted) stamps.push_back(p.stamp_ns);
  LoopCheckResult out;
  out.loops = loops.size();
  std::vector<double> translation, rotation;
  for (std::size_t i = 0; i < loops.size(); ++i) {
    const auto a = nearest(sorted, stamps, loops[i].from_ns, options.max_difference_s);
    const auto b = nearest(sorted, stamps, loops[i].to_ns, options.max_difference_s);
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
