// KeyframeSelector: the thesis's keyframe rule (docs/algorithms.md#rgb-d-visual-odometry).
//
// The motion of a frame since the last keyframe, delta = T_keyframe^-1 * T_frame, has size
//   e = min(2 pi - |r|, |r|) + |t|      (r: rotation vector [rad], t: translation [m])
// and the frame is
//   * dropped when it has fewer than good_match inliers (registration not trusted),
//   * dropped when e > e_error (motion too large to be a correct registration),
//   * skipped when e < e_key (too close to the last keyframe),
//   * a new keyframe otherwise.
// Defaults are the thesis's: good_match 4, E_error 0.3, E_key 0.06 (a sum of radians and metres,
// as the thesis defines it).
#pragma once

#include <Eigen/Geometry>

#include <cstddef>
#include <string_view>

namespace tessera::visual_slam {

struct KeyframeOptions {
  int good_match = 4;
  double e_error = 0.3;
  double e_key = 0.06;

  template <class V>
  void visit(V& v) {
    v("good_match", good_match, "fewer inliers than this: the frame is dropped");
    v("e_error", e_error, "motion size above this: dropped as too large [rad + m]");
    v("e_key", e_key, "motion size below this: too close to the last keyframe [rad + m]");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

enum class KeyframeDecision { kKeyframe, kSkip, kDropFewInliers, kDropTooLarge };
std::string_view decisionName(KeyframeDecision d);

/// e = min(2 pi - |r|, |r|) + |t| of a relative motion.
double motionSize(const Eigen::Isometry3d& delta);

struct KeyframeCounts {
  std::size_t keyframes = 0, skipped = 0, dropped_few_inliers = 0, dropped_too_large = 0;
};

class KeyframeSelector {
 public:
  /// Throws std::invalid_argument for bad options.
  explicit KeyframeSelector(const KeyframeOptions& options = {});

  /// The decision for a frame with `inliers` whose motion since the last keyframe is `delta`;
  /// counted in counts().
  KeyframeDecision decide(int inliers, const Eigen::Isometry3d& delta);

  const KeyframeCounts& counts() const { return counts_; }
  const KeyframeOptions& options() const { return options_; }

 private:
  KeyframeOptions options_;
  KeyframeCounts counts_;
};

}  // namespace tessera::visual_slam
