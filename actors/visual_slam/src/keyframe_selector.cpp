// KeyframeSelector: motion size and the thesis's drop / skip / keyframe rule.
#include <tessera/visual_slam/keyframe_selector.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace tessera::visual_slam {

void KeyframeOptions::validate() const {
  if (good_match < 0) throw std::invalid_argument("keyframes: good_match must be >= 0");
  if (!(e_key >= 0) || !(e_error > e_key) || !std::isfinite(e_error))
    throw std::invalid_argument("keyframes: need 0 <= e_key < e_error (finite)");
}

std::string_view decisionName(KeyframeDecision d) {
  switch (d) {
    case KeyframeDecision::kKeyframe:
      return "keyframe";
    case KeyframeDecision::kSkip:
      return "skip";
    case KeyframeDecision::kDropFewInliers:
      return "drop_few_inliers";
    case KeyframeDecision::kDropTooLarge:
      return "drop_too_large";
  }
  return "?";
}

double motionSize(const Eigen::Isometry3d& delta) {
  const double r = Eigen::AngleAxisd(delta.rotation()).angle();  // |r| in [0, pi]
  return std::min(2 * std::numbers::pi - r, r) + delta.translation().norm();
}

KeyframeSelector::KeyframeSelector(const KeyframeOptions& options) : options_(options) {
  options_.validate();
}

KeyframeDecision KeyframeSelector::decide(int inliers, const Eigen::Isometry3d& delta) {
  if (inliers < options_.good_match) {
    ++counts_.dropped_few_inliers;
    return KeyframeDecision::kDropFewInliers;
  }
  const double e = motionSize(delta);
  if (!(e <= options_.e_error)) {  // NaN counts as too large
    ++counts_.dropped_too_large;
    return KeyframeDecision::kDropTooLarge;
  }
  if (e < options_.e_key) {
    ++counts_.skipped;
    return KeyframeDecision::kSkip;
  }
  ++counts_.keyframes;
  return KeyframeDecision::kKeyframe;
}

}  // namespace tessera::visual_slam
