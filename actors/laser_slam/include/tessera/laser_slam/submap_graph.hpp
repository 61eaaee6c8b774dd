// SubmapGraph: the global level of the two-level laser SLAM
// (docs/algorithms.md#submap-hand-over-and-loop-detection). Nodes
// are submap origins (local map poses) in the map frame; edges are constraints between submaps
// (hand-overs from the submap builder, revisits from the loop detector or the camera network). A
// second constraint between the same two submaps is fused into the first by information weighting,
// so revisits do not grow the graph; the loop detector's scan matches of one pair share an error
// (closure_shared_std_*) that fusing them does not average away. The graph is re-optimised
// (pose_graph::optimize, warm-started from the current poses) whenever a constraint can change the
// optimum: a new revisit or a fusion. A hand-over to a new submap only extends the graph by a leaf
// and places it by composition.
//
// Lifelong mapping (docs/algorithms.md#lifelong-mapping): removeSubmap() marginalises a submap
// out of the graph (its neighbours tied by chained constraints, pose_graph::marginalizeNode); any
// later constraint naming it is rejected.
//
// Arrival order does not matter: a constraint naming a submap the graph does not know yet waits
// (pending) until that submap appears, through addSubmap() or a hand-over that places it.
// Frames: poses of submap origins in the map frame; a constraint i -> j is the pose of j's
// origin in i's frame with its covariance over (x [m], y [m], θ [rad]) in frame i.
// Plain C++ over Eigen; not thread-safe (one actor owns it).
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/pose_graph/optimizer.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <vector>

namespace tessera::laser_slam {

struct SubmapGraphOptions {
  /// Solver for re-optimisations. SGD first (cheap on a small graph) keeps a late loop closure
  /// that moves the estimate far from the basin Ceres alone would stay in.
  pose_graph::OptimizerOptions optimizer = [] {
    pose_graph::OptimizerOptions o;
    o.solver = pose_graph::Solver::kSgdCeres;
    // Each re-optimisation is warm-started from the previous optimum: 100 Ceres iterations
    // (not the 500 a cold start may need) bound the time one late closure can take.
    o.ceres.max_iterations = 100;
    o.ceres.huber_delta = 1.0;  // revisits are loop closures: robust
    return o;
  }();
  /// Constraints waiting for an unknown submap beyond this many are rejected (oldest first), so
  /// a stream naming submaps that never come cannot grow memory without bound.
  std::size_t max_pending = 1000;
  /// The scan matches fused into one edge i -> j were all found while the robot was in submap
  /// i, so they share one error: where the SLAM had placed that stretch of path in i. Fused,
  /// their information grows with their number only up to this shared error's (std per axis,
  /// isotropic; docs/algorithms.md#constraint-fusion). 0 = taken as independent, which made
  /// the camera floor's fused closures 0.15 m off against a 1 cm std (docs/benchmarks.md).
  double closure_shared_std_linear = 0.05;   ///< [m]
  double closure_shared_std_angular = 0.01;  ///< [rad]

  template <class V>
  void visit(V& v) {
    v("optimizer", optimizer,
      "solver of each re-optimisation (Huber on revisit edges, i.e. loop closures)");
    v("max_pending", max_pending,
      "constraints kept waiting for a submap not seen yet; beyond, the oldest are rejected");
    v("closure_shared_std_linear", closure_shared_std_linear,
      "[m] error the scan matches fused into one edge share (their pass's placement in the "
      "current submap); 0 = independent");
    v("closure_shared_std_angular", closure_shared_std_angular, "[rad] the same for heading");
  }
};

struct SubmapConstraintInput {
  int from = 0;
  int to = 0;
  tessera::Pose2 relative;  ///< pose of `to`'s origin in `from`'s frame
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();
  bool revisit = false;  ///< false: the hand-over from `from` to the new submap `to`
  /// Hand-overs: the builder was lost when `to` started (msg lost), so `to` is not where the
  /// hand-over says; the scan-level graph then does not join the two submaps at their shared scan.
  bool lost = false;
  /// A revisit found by matching one scan (loop detector): it shares its pass's error with the
  /// other matches of the same pair (SubmapGraphOptions::closure_shared_std_linear).
  bool scan_match = false;
};

class SubmapGraph {
 public:
  enum class Outcome {
    kAdded,      ///< a new edge
    kFused,      ///< merged into the edge between the same two submaps
    kDuplicate,  ///< the very same constraint again (e.g. re-sent): ignored
    kPending,    ///< names a submap not known yet: kept until it is
    kRejected,   ///< invalid (see lastError())
  };

  /// Throws std::invalid_argument on invalid options, naming the key inside SubmapGraphOptions.
  explicit SubmapGraph(SubmapGraphOptions options = {});

  /// A submap exists, with its origin guessed at `guess` in the map frame (used only when no
  /// constraint placed it yet). Resolves constraints that were waiting for it.
  void addSubmap(int id, const tessera::Pose2& guess);
  /// Adds or fuses a constraint (see Outcome). Pending constraints it unblocks are added too.
  Outcome addConstraint(const SubmapConstraintInput& c);

  /// Removes submap `id` (lifelong mapping), keeping what its constraints said about its
  /// neighbours. False (see lastError()) when it is unknown or is the anchor, the first node.
  bool removeSubmap(int id);
  bool removed(int id) const { return removed_.count(id) != 0; }
  /// Every submap removed so far, by increasing id.
  const std::set<int>& removedSubmaps() const { return removed_; }

  /// True when a constraint since the last optimize() can move the optimum.
  bool needsOptimization() const { return dirty_; }
  pose_graph::OptimizerSummary optimize();

  bool contains(int id) const { return graph_.contains(id); }
  tessera::Pose2 pose(int id) const;
  /// Every known submap's origin in the map frame, by id.
  std::map<int, tessera::Pose2> poses() const;
  std::size_t nodes() const { return static_cast<std::size_t>(graph_.size()); }
  std::size_t edges() const { return graph_.edges.size(); }
  std::size_t pending() const { return pending_.size(); }
  /// "from -> to" of each constraint still waiting for a submap.
  std::vector<std::string> pendingDescriptions() const;
  double chi2() const { return pose_graph::chi2(graph_); }
  const std::string& lastError() const { return last_error_; }
  const pose_graph::Graph2D& graph() const { return graph_; }

 private:
  Outcome insert(const SubmapConstraintInput& c);
  void resolvePending();
  /// Fuses a constraint into its pair's edge, scan matches with their pass's shared error (see
  /// options). True when the pair had an edge.
  bool fuseIntoPair(const pose_graph::Edge2D& edge, int from_id, int to_id, bool scan_match);

  SubmapGraphOptions options_;
  pose_graph::Graph2D graph_;
  std::vector<SubmapConstraintInput> pending_;
  // Exact repeats, bounded: the newest kMaxSeen keys (a re-send comes soon after the original).
  static constexpr std::size_t kMaxSeen = 4096;
  std::set<std::tuple<int, int, double, double, double>> seen_;
  std::deque<std::tuple<int, int, double, double, double>> seen_order_;
  std::set<int> removed_;
  // Per submap pair (lower id first, measurements in that direction): the scan matches fused as
  // independent, and everything else the pair's edge holds. The edge is their fusion, the
  // matches' part with the shared error added.
  struct PairParts {
    pose_graph::Measurement2D scan_matches;  // a pair is tracked from its first scan match
    std::optional<pose_graph::Measurement2D> others;
  };
  std::map<std::pair<int, int>, PairParts> pair_parts_;
  bool dirty_ = false;
  std::string last_error_;
};

}  // namespace tessera::laser_slam
