// graph_optimizer actor: the global level of the two-level laser SLAM around SubmapGraph
// (docs/algorithms.md#pose-graph).
//
// Subscribes:
//   submaps       msg::Submap            reliable   makes each submap a node (its globalPose is
//                                                   only a first guess)
//   constraints   msg::SubmapConstraint  reliable   hand-overs (submap builder) and revisits
//                                                   (loop detector, camera network)
//   trajectory    msg::PoseStamped       reliable, only with compose_trajectory: robot poses in
//                                                   the chained map frame (the submap builder's
//                                                   final_poses, which arrive at its stop)
// Publishes:
//   submap_poses  msg::SubmapPoses       after every re-optimisation, and in stop()
//   trajectory_final msg::PoseStamped    in stop(), with compose_trajectory: each trajectory pose
//                                        moved with its submap: optimised origin ⊕ (chained
//                                        origin⁻¹ ⊕ pose). A pose belongs to the first submap
//                                        whose last scan is not older than it.
// Writes (with an output directory, in stop()): graph.g2o (g2o_file), the final graph in g2o
// format: VERTEX_SE2 per submap origin (id = submap id, optimised pose), EDGE_SE2 per hand-over
// and fused revisit with its information matrix, FIX for the anchored first submap; it opens in
// g2o_viewer and `tessera graph optimize`.
// The optimiser runs in this actor's own handler, so the submap builder never waits for it
// (constraints that arrive meanwhile queue in the reliable mailbox). Each constraint that can
// move the optimum (a revisit, a fusion) triggers one optimisation, warm-started from the
// current poses; a hand-over only places its new submap.
// A constraint naming an unknown submap waits for it; at stop, any still waiting are reported
// by id in the log and counted (`constraints_unresolved`), never a crash.
//
// With scan_graph, stop() also builds the scan-level graph (ScanGraph, scan_graph.hpp): every
// scan of the finished submaps' trajectories (or every scan_node_every-th) becomes a node tied
// to its submap and to the previous scan node, and each scan-matched closure (scanInTo) ties its
// scan to the submap it matched instead of joining the two submaps rigidly. It starts from the
// submap-level optimum and is optimised once; the final submap_poses and trajectory_final come
// from it (a trajectory pose whose scan is in no submap's trajectory is moved with its submap as
// without it). The online optimisations, and so the loop detector's search centres, are the
// submap-level ones either way, and graph.g2o holds the submap-level graph.
#pragma once

#include <tessera/msg/submap.capnp.h>
#include <tessera/laser_slam/scan_graph.hpp>
#include <tessera/laser_slam/submap_graph.hpp>
#include <tessera/runtime/actor.hpp>

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace tessera::laser_slam {

struct GraphOptimizerActorOptions {
  std::string solver = "sgd+ceres";
  int sgd_iterations = 10;
  int ceres_iterations = 100;
  double huber_delta = 1.0;
  std::string frame_id = "map";
  bool compose_trajectory = false;
  std::string g2o_file = "graph.g2o";
  bool scan_graph = false;
  int scan_node_every = 1;
  double scan_sigma_linear = 0.5;
  double scan_sigma_angular = 0.1;
  double chain_sigma_linear = 0.02;
  double chain_sigma_angular = 0.005;
  int scan_ceres_iterations = 50;
  double scan_huber_delta = 1.0;
  bool scan_shared_handovers = false;

  template <class V>
  void visit(V& v) {
    v("compose_trajectory", compose_trajectory,
      "subscribe to trajectory and publish it re-expressed in the optimised submaps at stop");
    v("solver", solver, "sgd | ceres | sgd+ceres: solver of each re-optimisation");
    v("sgd_iterations", sgd_iterations, "SGD passes before Ceres (sgd, sgd+ceres)");
    v("ceres_iterations", ceres_iterations, "Ceres iterations (max) per re-optimisation");
    v("huber_delta", huber_delta,
      "Huber scale on revisit (loop-closure) edges, whitened units; 0 = plain least squares");
    v("frame_id", frame_id, "frame of the published poses");
    v("g2o_file", g2o_file,
      "final pose graph written here, in the output directory, at stop (g2o); empty: none");
    v("scan_graph", scan_graph,
      "at stop, optimise a scan-level graph (scans as nodes, closures on their scans) and take "
      "the final submap poses and trajectory from it");
    v("scan_node_every", scan_node_every,
      "scan_graph: every n-th scan of a submap is a node (closed scans always); the others are "
      "interpolated");
    v("scan_sigma_linear", scan_sigma_linear, "scan_graph: [m] std of a scan's pose in its submap");
    v("scan_sigma_angular", scan_sigma_angular, "scan_graph: [rad] the same for heading");
    v("chain_sigma_linear", chain_sigma_linear,
      "scan_graph: [m] std of the motion between consecutive scan nodes; 0 = no such edges");
    v("chain_sigma_angular", chain_sigma_angular, "scan_graph: [rad] the same for heading");
    v("scan_ceres_iterations", scan_ceres_iterations,
      "scan_graph: Ceres iterations (max) of the scan-level optimisation");
    v("scan_huber_delta", scan_huber_delta,
      "scan_graph: Huber scale on scan closure edges, whitened units; 0 = plain least squares");
    v("scan_shared_handovers", scan_shared_handovers,
      "scan_graph: keep the hand-over between two submaps that share a scan node (false: they "
      "are joined through their scans only)");
  }
};

class GraphOptimizerActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit GraphOptimizerActor(GraphOptimizerActorOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  void summarize(Summary& out) const override;

  const SubmapGraph& graph() const { return graph_; }
  const ScanGraph& scanGraph() const { return scan_graph_; }

 private:
  void onSubmap(const Message<msg::Submap>& m);
  void onConstraint(const Message<msg::SubmapConstraint>& m);
  void optimizeAndPublish();
  void addToScanGraph(const Message<msg::SubmapConstraint>& m, const SubmapConstraintInput& c);
  /// At stop: the scan-level optimisation; false when it could not run.
  bool optimizeScanGraph();
  void publishPoses(const std::map<int, tessera::Pose2>& poses, double chi2, int iterations);
  void publishComposedTrajectory();
  void writeGraph();

  GraphOptimizerActorOptions options_;
  SubmapGraph graph_;
  ScanGraph scan_graph_;
  bool scan_optimized_ = false;
  Publisher<msg::SubmapPoses> poses_pub_;
  Publisher<msg::PoseStamped> trajectory_pub_;
  struct SubmapSpan {
    Nanos last_stamp = 0;
    tessera::Pose2 chained;  // origin in the chained map frame, as the builder published it
  };
  std::map<int, SubmapSpan> spans_;
  std::vector<std::pair<Nanos, tessera::Pose2>> trajectory_;
  Nanos last_stamp_ = 0;
  std::string output_dir_, graph_path_, write_error_;
  std::uint64_t submaps_ = 0, constraints_ = 0, added_ = 0, fused_ = 0, duplicates_ = 0;
  std::uint64_t rejected_ = 0, optimizations_ = 0, published_ = 0, solver_failures_ = 0;
  double optimize_seconds_ = 0.0, last_chi2_ = 0.0;
  std::uint64_t scan_rejected_ = 0, scan_composed_ = 0;
  double scan_seconds_ = 0.0, scan_chi2_ = 0.0;
  int scan_iterations_ = 0;
};

}  // namespace tessera::laser_slam
