#include <tessera/geometry/pose_history.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tessera {

PoseHistory::PoseHistory(std::size_t capacity, double max_gap_s)
    : capacity_(capacity), max_gap_s_(max_gap_s) {
  if (capacity < 2) throw std::invalid_argument("PoseHistory: capacity must be >= 2 poses");
  if (!(std::isfinite(max_gap_s) && max_gap_s > 0))
    throw std::invalid_argument("PoseHistory: max_gap_s must be > 0");
}

bool PoseHistory::add(std::int64_t stamp_ns, const Pose2& pose) {
  if (!pose.isFinite()) return false;
  // Poses normally arrive in order: append; otherwise insert in place (or replace a duplicate).
  auto it = std::lower_bound(poses_.begin(), poses_.end(), stamp_ns,
                             [](const Entry& e, std::int64_t t) { return e.stamp_ns < t; });
  if (it != poses_.end() && it->stamp_ns == stamp_ns) {
    it->pose = pose;
  } else {
    poses_.insert(it, {stamp_ns, pose});
  }
  while (poses_.size() > capacity_) poses_.pop_front();
  return true;
}

PoseHistory::Lookup PoseHistory::at(std::int64_t stamp_ns, Pose2& out) const {
  if (poses_.empty() || stamp_ns > poses_.back().stamp_ns) return Lookup::kWait;
  auto next = std::lower_bound(poses_.begin(), poses_.end(), stamp_ns,
                               [](const Entry& e, std::int64_t t) { return e.stamp_ns < t; });
  if (next->stamp_ns == stamp_ns) {
    out = next->pose;
    return Lookup::kExact;
  }
  if (next == poses_.begin()) return Lookup::kTooOld;
  const auto prev = std::prev(next);
  const std::int64_t gap = next->stamp_ns - prev->stamp_ns;
  if (static_cast<double>(gap) * 1e-9 > max_gap_s_) return Lookup::kGap;
  const double t = static_cast<double>(stamp_ns - prev->stamp_ns) / static_cast<double>(gap);
  out = interpolate(prev->pose, next->pose, t);
  return Lookup::kInterpolated;
}

}  // namespace tessera
