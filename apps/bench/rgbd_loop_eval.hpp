// Loop closure beside the tracker in `tessera bench rgbd`: each keyframe the tracker inserts goes
// through the LoopDetector (bag of words, geometric verification); verified loops go into a
// KeyframeGraph with the tracker's keyframe poses, optimised once at the end. Figures against the
// dataset's poses (docs/benchmarks.md, loop closure):
//  * a loop is false when its relative pose differs from the ground-truth one by more than
//    max_error_m in translation or max_error_deg in rotation;
//  * a ground-truth revisit is a keyframe j with an earlier keyframe i, at least
//    database.recent_excluded keyframes before it (the ones the detector never proposes), such
//    that at least min_overlap of j's 3D points, moved into i's camera with the true relative
//    pose, land in i's image at depths in (0.3, 6) m; recall = keyframes whose accepted loop is
//    true / revisit keyframes;
//  * keyframe ATE (rigid alignment) of the tracker's keyframe poses and of the graph's after
//    optimising with the loops, and the keyframes' corrections for moving every frame.
// Poses given here are the tracked (colour) camera's; ground truth comes as the same camera.
#pragma once

#include <tessera/visual_slam/keyframe_graph.hpp>
#include <tessera/visual_slam/loop_detector.hpp>
#include <tessera/visual_slam/tracker.hpp>

#include <Eigen/Geometry>

#include <cstddef>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::app {

struct LoopEvalFigures {
  std::size_t keyframes = 0, queries = 0, candidates = 0, accepted = 0, false_loops = 0;
  std::size_t revisits = 0, true_detected = 0;  ///< recall = true_detected / revisits
  std::map<std::string, std::size_t> rejected_by;
  double ms_per_keyframe = 0;  ///< loop detection, mean over keyframes [ms]
  double keyframe_ate_m = 0, keyframe_ate_loops_m = 0;
  double worst_true_error_m = 0;  ///< largest translation error among true accepted loops
  std::string vocabulary;         ///< "file" or "bootstrap"
  /// Each keyframe's tracked and optimised pose (empty without loops), to move the frames with.
  std::vector<visual_slam::KeyframeCorrection> corrections;
};

class LoopEvaluation {
 public:
  /// `vocabulary_path` empty: bootstrap. Throws ConfigError for bad options or files.
  LoopEvaluation(const visual_slam::LoopDetectorOptions& options,
                 const std::string& vocabulary_path, const visual_slam::PinholeCamera& camera,
                 double max_error_m, double max_error_deg, double min_overlap);

  /// The tracker's newest keyframe and the true camera-to-world of its frame (if known).
  void addKeyframe(const visual_slam::Keyframe& keyframe, int inliers,
                   const std::optional<Eigen::Isometry3d>& truth);
  /// Ground-truth revisits, the graph optimisation and the ATEs.
  LoopEvalFigures finish();

 private:
  struct Entry {
    Eigen::Isometry3d estimate, truth;
    bool has_truth = false;
    double timestamp = 0;
    std::vector<Eigen::Vector3d> points;
  };

  visual_slam::LoopDetectorOptions options_;
  visual_slam::PinholeCamera camera_;
  double max_error_m_, max_error_deg_, min_overlap_;
  std::unique_ptr<visual_slam::LoopDetector> detector_;
  std::vector<Entry> entries_;  ///< index = keyframe id
  struct Loop {
    std::size_t from, to;
    Eigen::Isometry3d relative;
    Eigen::Matrix<double, 6, 6> covariance;
  };
  std::vector<Loop> loops_;
  std::vector<int> inliers_;
  LoopEvalFigures f_;
  double ms_ = 0;
};

}  // namespace tessera::app
