// ScanGraph: a scan-level pose graph for the global level of docs/algorithms.md#scan-level-graph
// (sparse pose adjustment in the manner of Cartographer). Nodes are the submap origins and the
// robot poses at scans; edges are
//   * intra-submap: submap k -> scan s, the scan's smoothed pose in k (a fixed, isotropic-in-xy
//     information: every scan is as well placed in its own submap as the map built from it);
//   * chain: scan s -> the next scan node of the same submap, their smoothed relative motion (so
//     a scan pulled by a closure bends its neighbours instead of jumping away from them);
//   * loop: matched submap j -> scan s, the scan's matched pose in j with the matcher's
//     covariance (robust), instead of a submap -> submap edge fused over all the closures;
//   * submap -> submap: hand-overs, and revisits that name no scan (or whose scan is not a
//     node), fused as in SubmapGraph.
// A scan shared by two submaps (the one that ended a submap starts the next) is one node with an
// edge from each. A closure can so hold a scan between its own submap and the one it closed
// against, and a submap's internal drift is no longer carried rigidly by all its scans. Not after
// a lost hand-over (SubmapConstraintInput::lost: the builder lost the map, e.g. a kidnapped
// robot): the new submap's first scan is a node of its own, or the shared node would tie the new
// submap to where the old one ended, which is what being lost says is wrong.
//
// Inputs are collected as they come (any order); optimize() builds the graph from all of them,
// starting each node where the previous optimize() left it (warm start), and new ones where the
// caller says (a submap: e.g. SubmapGraph's optimum; a scan: its submap's start ⊕ its smoothed
// pose).
// Only every `node_every`-th scan of a submap is a node (plus its first and last scans and every
// scan a closure names); scanPose() interpolates the others between the neighbouring nodes.
// Frames: submap origins and scans in the map frame; trajectories in their submap's frame.
// Stamps in nanoseconds; two stamps within `stamp_tolerance_ns` are the same scan. Plain C++ over
// Eigen; not thread-safe (one actor owns it).
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/laser_slam/submap_graph.hpp>
#include <tessera/pose_graph/optimizer.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace tessera::laser_slam {

struct ScanGraphOptions {
  /// Every n-th scan of a submap is a node (>= 1); scans a closure names always are.
  int node_every = 1;
  /// Standard deviation of a scan's pose in its own submap ([m] per axis, [rad]). Loose: the
  /// smoothed poses drift within a 20 m submap, and the chain edges keep the local shape (on
  /// Intel 0.05 m / 0.01 rad gave 0.122 m relations error, 0.2 / 0.05 0.115, 0.5 / 0.1 0.114).
  double intra_sigma_linear = 0.5;
  double intra_sigma_angular = 0.1;
  /// Standard deviation of the relative motion between consecutive scan nodes; linear 0 = no
  /// chain edges.
  double chain_sigma_linear = 0.02;
  double chain_sigma_angular = 0.005;
  /// Keep a hand-over between two submaps that share a scan node. It repeats what the shared
  /// scan's two intra-submap edges say (the builder's pose at the cut), at its own sigma;
  /// without it the submaps are joined only through their scans. Hand-overs between submaps
  /// without a shared scan are always kept.
  bool shared_handovers = false;
  /// Two stamps closer than this name the same scan (stamps went through seconds upstream).
  std::int64_t stamp_tolerance_ns = 1000;
  /// Warm-started from a good estimate: Ceres alone (SGD's incremental parameterisation wants
  /// nodes in trajectory order, which submap + scan nodes are not). Huber on loop edges.
  pose_graph::OptimizerOptions optimizer = [] {
    pose_graph::OptimizerOptions o;
    o.solver = pose_graph::Solver::kCeres;
    o.ceres.max_iterations = 50;
    o.ceres.huber_delta = 1.0;
    return o;
  }();

  template <class V>
  void visit(V& v) {
    v("node_every", node_every,
      "every n-th scan of a submap is a node (its first and last, and closed scans, always); "
      "the others are interpolated");
    v("intra_sigma_linear", intra_sigma_linear, "[m] std of a scan's pose in its submap");
    v("intra_sigma_angular", intra_sigma_angular, "[rad] the same for heading");
    v("chain_sigma_linear", chain_sigma_linear,
      "[m] std of the motion between consecutive scan nodes; 0 = no such edges");
    v("chain_sigma_angular", chain_sigma_angular, "[rad] the same for heading");
    v("shared_handovers", shared_handovers,
      "keep the hand-over between two submaps that share a scan node (false: they are joined "
      "through their scans only)");
    v("stamp_tolerance_ns", stamp_tolerance_ns, "[ns] stamps closer than this name the same scan");
    v("optimizer", optimizer,
      "solver of the scan-level optimisation (Huber on loop edges); ceres: SGD wants nodes in "
      "trajectory order, which submap and scan nodes are not");
  }
};

/// A scan's pose with its stamp [ns].
struct StampedPose2 {
  std::int64_t stamp_ns = 0;
  tessera::Pose2 pose;
};

/// A loop closure made by matching one scan: the robot's pose at `stamp_ns` in submap
/// `matched`'s frame, with its covariance (x, y, θ in that frame).
struct ScanLoopInput {
  int matched = 0;
  std::int64_t stamp_ns = 0;
  tessera::Pose2 pose;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();
};

class ScanGraph {
 public:
  /// Throws std::invalid_argument on invalid options, naming the key inside ScanGraphOptions.
  explicit ScanGraph(ScanGraphOptions options = {});

  /// A finished submap's smoothed trajectory (its own frame, increasing stamps). Returns false
  /// (see lastError()) for a repeated id, decreasing stamps or a non-finite pose.
  bool addSubmap(int id, std::vector<StampedPose2> trajectory);
  /// A submap -> submap constraint (hand-over, or a revisit that names no scan). Returns false
  /// for the invalid ones SubmapGraph rejects too.
  bool addConstraint(const SubmapConstraintInput& c);
  /// A scan-matched closure; `fallback` is the same closure as a submap -> submap revisit, used
  /// when the scan is in no submap's trajectory. Returns false for a non-finite pose or a
  /// covariance that is not positive definite.
  bool addLoop(const ScanLoopInput& loop, const SubmapConstraintInput& fallback);

  /// Builds the graph from everything added and optimises it. `start`: where each submap the
  /// previous optimize() did not place starts; a submap in neither is left out, with its scans
  /// and the constraints naming it. Throws pose_graph::GraphError if the solver cannot work on
  /// the graph (e.g. nothing to optimise).
  pose_graph::OptimizerSummary optimize(const std::map<int, tessera::Pose2>& start);

  /// After optimize(): each submap origin in the map frame.
  std::map<int, tessera::Pose2> submapPoses() const;
  /// After optimize(): the robot at a scan of some submap's trajectory (a node, or interpolated
  /// between its submap's neighbouring nodes). False when no submap holds that stamp.
  bool scanPose(std::int64_t stamp_ns, tessera::Pose2& out) const;

  std::size_t submaps() const { return trajectories_.size(); }
  std::size_t nodes() const { return static_cast<std::size_t>(graph_.size()); }
  std::size_t edges() const { return graph_.edges.size(); }
  std::size_t scanNodes() const { return scan_nodes_; }
  /// Closures of the last optimize() attached to a scan node / put on the submap level.
  std::size_t loopsOnScans() const { return loops_on_scans_; }
  std::size_t loopsOnSubmaps() const { return loops_on_submaps_; }
  const std::string& lastError() const { return last_error_; }
  const pose_graph::Graph2D& graph() const { return graph_; }

 private:
  struct Loop {
    ScanLoopInput scan;
    SubmapConstraintInput fallback;
  };
  struct Trajectory {
    std::vector<StampedPose2> scans;
    std::vector<int> node_of;  // graph index of each scan's node, -1 when not a node
  };
  bool checkCovariance(const Eigen::Matrix3d& cov, const std::string& what);
  /// Index into trajectories_[id].scans of the scan at `stamp`, or -1.
  int find(const Trajectory& t, std::int64_t stamp) const;
  void addScanNodes(int submap, Trajectory& t, const std::vector<std::int64_t>& closed,
                    std::map<std::int64_t, int>& node_by_stamp,
                    std::set<std::pair<int, int>>& sharing);

  ScanGraphOptions options_;
  std::map<int, Trajectory> trajectories_;
  std::vector<SubmapConstraintInput> constraints_;
  std::set<int> lost_starts_;  // submaps started by a lost hand-over: no shared first scan
  std::vector<Loop> loops_;
  std::map<int, Eigen::Vector3d> warm_submaps_;         // id -> last optimised origin
  std::map<std::int64_t, Eigen::Vector3d> warm_scans_;  // scan stamp -> last optimised pose
  pose_graph::Graph2D graph_;
  std::size_t scan_nodes_ = 0, loops_on_scans_ = 0, loops_on_submaps_ = 0;
  std::string last_error_;
};

}  // namespace tessera::laser_slam
