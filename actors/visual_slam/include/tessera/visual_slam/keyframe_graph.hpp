// KeyframeGraph: the SE(3) pose graph of RGB-D keyframes (docs/algorithms.md#rgb-d-visual-odometry)
// over the pose_graph core's Graph3D and its Ceres solver.
//
//  * Each keyframe is a node; the first is fixed (it anchors the world frame).
//  * Odometry edges join consecutive keyframes (by arrival): the relative pose of the tracker's
//    poses, T_prev⁻¹ T_new, with a fixed standard deviation (odometry_sigma_*), scaled by the
//    tracking inlier count when inlier_weighting is on. A new keyframe is placed at the
//    previous keyframe's optimised pose composed with that relative pose, so keyframes after a
//    correction start where the correction put their predecessor.
//  * Loop edges (from a loop detector) carry their own covariance and are `robust`: the Ceres
//    stage puts a Huber loss (optimizer.ceres.huber_delta, whitened units) on them, so one wrong
//    loop pulls with a bounded force instead of bending the whole graph.
//  * Each accepted loop edge makes needsOptimization() true; optimize() then runs the solver,
//    warm-started from the current poses.
// A loop naming a keyframe not seen yet waits (pending) until both ends exist; one naming a
// keyframe the graph no longer holds (trimmed, or rejected: ids only grow) is rejected.
//
// Lifelong mode (trimming.enabled; docs/algorithms.md#lifelong-mapping): trim() removes the
// keyframes a newer kept keyframe covers — within trimming.radius_m and trimming.angle_rad of it
// in the optimised graph, at least trimming.min_age keyframes newer — marginalising each
// (pose_graph::marginalizeNode: its edges become chained edges between its neighbours), so a
// robot driving the same building lap after lap keeps about one lap of keyframes. Only the
// optimised poses are compared: before a loop has tied a revisit to the old keyframes, drift
// could put unrelated views side by side, so trim() is meant to run after optimize().
//
// Conventions are pose_graph.hpp's (g2o's): an edge a -> b measures the pose of b in the frame of
// a, information over (translation, rotation) where the rotation error is the imaginary part of
// the error quaternion (about half the angle). Poses are camera-to-world; metres, radians.
// Not thread-safe: one caller at a time.
#pragma once

#include <tessera/geometry/pose3.hpp>
#include <tessera/pose_graph/optimizer.hpp>
#include <tessera/pose_graph/pose_graph.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace tessera::visual_slam {

/// Which keyframes lifelong mode removes (see the top of the file).
struct KeyframeTrimmingOptions {
  bool enabled = false;
  double radius_m = 0.3;    ///< [m] a newer keyframe this close covers an older one...
  double angle_rad = 0.35;  ///< [rad] ...if it also looks within this angle (20 deg) of it
  int min_age = 50;         ///< [keyframes] the covering keyframe is at least this much newer

  template <class V>
  void visit(V& v) {
    v("enabled", enabled,
      "lifelong mode: marginalise keyframes a newer kept one covers (after each optimisation)");
    v("radius_m", radius_m, "a newer keyframe within this distance may cover an older one [m]");
    v("angle_rad", angle_rad, "...when their orientations differ by less than this [rad]");
    v("min_age", min_age,
      "keyframes between the two at least (recent keyframes are never trimmed or covering)");
  }
};

struct KeyframeGraphOptions {
  pose_graph::OptimizerOptions optimizer = defaultOptimizer();
  KeyframeTrimmingOptions trimming;
  double odometry_sigma_translation = 0.01;  ///< [m] per odometry edge
  double odometry_sigma_rotation = 0.01;     ///< [rad] per odometry edge
  /// Scale the odometry information by inliers / reference_inliers (clamped to [0.1, 10]), so a
  /// weakly tracked step is trusted less. Off, or without an inlier count: the fixed sigmas.
  bool inlier_weighting = true;
  int reference_inliers = 100;

  static pose_graph::OptimizerOptions defaultOptimizer() {
    pose_graph::OptimizerOptions o;
    o.solver = pose_graph::Solver::kCeres;  // the tracker's poses are a good start: no SGD stage
    o.ceres.max_iterations = 100;
    o.ceres.huber_delta = 1.0;
    return o;
  }

  template <class V>
  void visit(V& v) {
    v("optimizer", optimizer, "the solver (loop edges get optimizer.ceres.huber_delta)");
    v("odometry_sigma_translation", odometry_sigma_translation,
      "standard deviation of an odometry edge's translation [m]");
    v("odometry_sigma_rotation", odometry_sigma_rotation,
      "standard deviation of an odometry edge's rotation [rad]");
    v("inlier_weighting", inlier_weighting,
      "scale odometry information by tracking inliers / reference_inliers (0.1x to 10x)");
    v("reference_inliers", reference_inliers, "inlier count that gets the plain sigmas");
    v("trimming", trimming, "lifelong mode: which covered keyframes are marginalised");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

/// A measured pose of keyframe `to` in the frame of keyframe `from`.
struct LoopConstraint {
  std::int64_t from = 0, to = 0;
  Pose3 relative;
  /// 6x6 over (x y z rx ry rz), rotation as a rotation vector [rad]; converted to the graph's
  /// quaternion-error information.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
};

class KeyframeGraph {
 public:
  enum class Outcome { kAdded, kPending, kRejected };

  /// Throws std::invalid_argument for bad options.
  explicit KeyframeGraph(const KeyframeGraphOptions& options);

  /// Adds a keyframe with the tracker's pose (and its tracking inliers, 0 = unknown). False
  /// (lastError() says why) for a repeated id or a non-finite pose.
  bool addKeyframe(std::int64_t id, const Pose3& tracker_pose, int inliers = 0);
  /// kRejected (lastError()) for a self-loop, non-finite values, a covariance that is not
  /// symmetric positive definite or an end the graph no longer holds (an id at or below the
  /// newest keyframe's that is not in the graph); kPending when an end is not a keyframe yet.
  Outcome addLoop(const LoopConstraint& loop);

  bool needsOptimization() const { return dirty_; }
  /// Throws pose_graph::GraphError when the solver cannot run (the poses stay as they were).
  pose_graph::OptimizerSummary optimize();
  /// Lifelong mode: marginalises every keyframe covered by a newer kept one and returns their
  /// ids (ascending); nothing when trimming is off. The first keyframe (the anchor) and the
  /// newest trimming.min_age are never removed.
  std::vector<std::int64_t> trim();

  std::size_t keyframes() const { return static_cast<std::size_t>(graph_.size()); }
  std::size_t loops() const { return loops_; }
  std::size_t trimmed() const { return trimmed_; }
  std::size_t pending() const { return pending_.size(); }
  /// Optimised (or initial) camera-to-world of every keyframe, by id.
  std::map<std::int64_t, Pose3> poses() const;
  const pose_graph::Graph3D& graph() const { return graph_; }
  double chi2() const;
  const std::string& lastError() const { return error_; }

 private:
  Outcome insertLoop(const LoopConstraint& loop);

  KeyframeGraphOptions options_;
  pose_graph::Graph3D graph_;
  std::optional<std::int64_t> last_id_;
  Pose3 last_tracker_pose_;
  std::vector<LoopConstraint> pending_;
  std::size_t loops_ = 0, trimmed_ = 0;
  bool dirty_ = false;
  std::string error_;
};

/// A keyframe's pose before and after optimisation, at its time.
struct KeyframeCorrection {
  std::int64_t stamp_ns = 0;
  Pose3 tracked, optimised;
};

/// Every frame's pose moved with the optimisation of the keyframes: a frame follows the latest
/// keyframe at or before its time (of those given; the keyframe_graph actor bakes a trimmed
/// keyframe's correction into its frames when it trims it), T' =
/// T_k,optimised · T_k,tracked⁻¹ · T. The correction acts in the world frame, so frames may be
/// reported in another camera frame than the keyframes (7-Scenes: the depth camera). Frames before
/// the first keyframe stay as they are. `frames`: (time [ns], tracked camera-to-world); `keyframes`
/// in any order.
std::vector<Pose3> correctFramePoses(const std::vector<std::pair<std::int64_t, Pose3>>& frames,
                                     std::vector<KeyframeCorrection> keyframes);

}  // namespace tessera::visual_slam
