// checkLoops: are loop closures true? Each measured relative pose (the pose at `to` in the frame
// of the pose at `from`, as a loop detector reports it) is compared with the reference
// trajectory's relative pose between the same times (docs/algorithms.md#loop-closure).
//
// A loop is false when its translation error exceeds max_error_m or its rotation error
// max_error_deg. Loops whose times have no reference pose within max_difference_s are counted
// as unchecked. Precision = true / checked. SE(3) poses, metres, degrees.
#pragma once

#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/geometry/pose3.hpp>
#include <tessera/mapping/trajectory_io.hpp>

#include <cstdint>
#include <vector>

namespace tessera::evaluation {

struct RelativeMeasurement {
  std::int64_t from_ns = 0, to_ns = 0;
  Pose3 relative;  ///< pose at to_ns in the frame of the pose at from_ns
};

struct LoopCheckOptions {
  double max_error_m = 0.10;
  double max_error_deg = 5.0;
  double max_difference_s = 0.02;  ///< [s] largest stamp difference to a reference pose
};

struct LoopCheckResult {
  std::size_t loops = 0, checked = 0, false_loops = 0;
  ErrorStats translation;  ///< [m] over the checked loops
  ErrorStats rotation_deg;
  double worst_true_m = 0;                 ///< largest translation error among the true loops
  std::vector<std::size_t> false_indices;  ///< into the measurements
};

LoopCheckResult checkLoops(const std::vector<RelativeMeasurement>& loops,
                           const std::vector<mapping::TumPose>& reference,
                           const LoopCheckOptions& options = {});

}  // namespace tessera::evaluation
