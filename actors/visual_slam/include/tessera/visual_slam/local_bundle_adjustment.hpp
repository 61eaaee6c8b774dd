// Local bundle adjustment: the poses of the newest keyframes and the map points they see,
// refined together (Ceres) against every observation of those points in the window and in a
// few older keyframes held fixed (docs/algorithms.md#rgb-d-visual-odometry).
//
// A map point is identified by Keyframe::point_ids: a keyframe feature that matched a map point
// while tracking carries that point's id, so the keyframes that saw it share it. Each
// observation gives a reprojection residual [px] and, from the keyframe's own depth reading,
// the disparity residual fx b / z_predicted - fx b / z_measured [px] (b = depth_baseline; the
// same RGB-D residual as the motion-only refinement of PoseEstimator), under a Huber loss.
// Points seen by only one keyframe are left out (they cannot correct a pose). The older
// keyframes fix the gauge; with none (the first keyframes), the oldest of the window is fixed.
// After the solve every copy of an adjusted point (Keyframe::points_world) gets its new position
// in the keyframes considered, and the window's keyframes their new poses.
//
// Units: metres, pixels. Not thread-safe; runs in the caller's thread.
#pragma once

#include <tessera/visual_slam/camera.hpp>

#include <cstddef>
#include <vector>

namespace tessera::visual_slam {

struct Keyframe;

struct LocalBundleAdjustmentOptions {
  int keyframes = 0;             ///< newest keyframes adjusted (their poses); 0 = off
  int fixed_keyframes = 10;      ///< older keyframes whose observations enter with fixed poses
  int iterations = 5;            ///< Levenberg-Marquardt iterations per adjustment
  double huber_delta = 2.0;      ///< [px] Huber loss width
  double depth_baseline = 0.08;  ///< [m] b of the disparity residual; 0 = reprojection only

  template <class V>
  void visit(V& v) {
    v("local_ba_keyframes", keyframes,
      "local bundle adjustment: newest keyframes whose poses and points are refined at each "
      "new keyframe (0 = off)");
    v("local_ba_fixed_keyframes", fixed_keyframes,
      "local bundle adjustment: older keyframes seeing the same points, held fixed");
    v("local_ba_iterations", iterations, "local bundle adjustment: solver iterations");
    v("local_ba_huber", huber_delta, "local bundle adjustment: Huber loss width [px]");
    v("local_ba_depth_baseline", depth_baseline,
      "local bundle adjustment: baseline of the depth (disparity) residual [m] (0 = off)");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

struct LocalBundleAdjustmentStats {
  std::size_t adjusted_keyframes = 0, fixed_keyframes = 0, points = 0, observations = 0;
  double initial_cost = 0, final_cost = 0;
  bool ran = false;
};

/// Adjusts the newest options.keyframes keyframes of `keyframes` (poses) and the points they
/// share with each other or with the options.fixed_keyframes before them. Does nothing (ran =
/// false) when off, with fewer than two keyframes, or without shared points.
LocalBundleAdjustmentStats adjustLocalWindow(std::vector<Keyframe>& keyframes,
                                             const PinholeCamera& camera,
                                             const LocalBundleAdjustmentOptions& options);

}  // namespace tessera::visual_slam
