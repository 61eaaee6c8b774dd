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
// With scan_graph.enabled, stop() also builds the scan-level graph (ScanGraph, scan_graph.hpp):
// every scan of the finished submaps' trajectories (or every scan_graph.node_every-th) becomes a
// node tied to its submap and to the previous scan node, and each scan-matched closure (scanInTo)
// ties its scan to the submap it matched instead of joining the two submaps rigidly. It starts
// from the submap-level optimum and is optimised once; the final submap_poses and
// trajectory_final come from it (a trajectory pose whose scan is in no submap's trajectory is
// moved with its submap as without it). The online optimisations, and so the loop detector's
// search centres, are the submap-level ones either way, and graph.g2o holds the submap-level
// graph.
//
// With lifelong.enabled (docs/algorithms.md#lifelong-mapping), each finished submap's footprint
// goes to a SubmapTrimmer; after it, the submaps newer ones cover are marginalised out of the
// graph (SubmapGraph::removeSubmap), and every later submap_poses lists them in `trimmed`, so the
// loop detector and the map assembler drop them too. The graph's anchor is never trimmed.
// Lifelong mode keeps nothing per scan, so it refuses scan_graph.enabled and compose_trajectory.
#pragma once

#include <tessera/msg/submap.capnp.h>
#include <tessera/laser_slam/scan_graph.hpp>
#include <tessera/laser_slam/submap_graph.hpp>
#include <tessera/laser_slam/submap_trimmer.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace tessera::laser_slam {

/// The scan-level graph of stop(): off unless `enabled`; its other keys are ScanGraph's own.
struct ScanGraphStage {
  bool enabled = false;
  ScanGraphOptions options;

  template <class V>
  void visit(V& v) {
    v("enabled", enabled,
      "at stop, optimise a scan-level graph (scans as nodes, closures on their scans) and take "
      "the final submap poses and trajectory from it");
    options.visit(v);  // ScanGraph's keys sit beside `enabled`, in the same group
  }
};

/// Lifelong mapping: off unless `enabled`; its other keys are SubmapTrimmer's own.
struct LifelongStage {
  bool enabled = false;
  SubmapTrimmerOptions trimmer;

  template <class V>
  void visit(V& v) {
    v("enabled", enabled,
      "trim submaps that newer ones cover: removed from the graph (their constraints chained "
      "onto their neighbours) and listed in submap_poses.trimmed");
    trimmer.visit(v);
  }
};

struct GraphOptimizerActorOptions {
  SubmapGraphOptions graph;
  ScanGraphStage scan_graph;
  LifelongStage lifelong;
  std::string frame_id = "map";
  bool compose_trajectory = false;
  std::string g2o_file = "graph.g2o";

  template <class V>
  void visit(V& v) {
    v("graph", graph, "the submap-level graph, re-optimised online");
    v("scan_graph", scan_graph, "the scan-level graph, optimised once at stop");
    v("lifelong", lifelong, "lifelong mapping: submaps covered by newer ones are trimmed");
    v("compose_trajectory", compose_trajectory,
      "subscribe to trajectory and publish it re-expressed in the optimised submaps at stop");
    v("frame_id", frame_id, "frame of the published poses");
    v("g2o_file", g2o_file,
      "final pose graph written here, in the output directory, at stop (g2o); empty: none");
  }

  /// The flat keys of earlier versions, now inside the graph and scan_graph groups.
  static constexpr RenamedKey kRenamedKeys[] = {
      {"solver", "graph.optimizer.solver"},
      {"sgd_iterations", "graph.optimizer.sgd.iterations"},
      {"ceres_iterations", "graph.optimizer.ceres.max_iterations"},
      {"huber_delta", "graph.optimizer.ceres.huber_delta"},
      // Was a bool: the YAML `scan_graph: true` (a value where the group is) names this too.
      {"scan_graph", "scan_graph.enabled"},
      {"scan_node_every", "scan_graph.node_every"},
      {"scan_sigma_linear", "scan_graph.intra_sigma_linear"},
      {"scan_sigma_angular", "scan_graph.intra_sigma_angular"},
      {"chain_sigma_linear", "scan_graph.chain_sigma_linear"},
      {"chain_sigma_angular", "scan_graph.chain_sigma_angular"},
      {"scan_ceres_iterations", "scan_graph.optimizer.ceres.max_iterations"},
      {"scan_huber_delta", "scan_graph.optimizer.ceres.huber_delta"},
      {"scan_shared_handovers", "scan_graph.shared_handovers"},
  };
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
  /// Lifelong: removes the submaps newer ones cover (graph_.removedSubmaps() lists them).
  void trimCovered();
  void addToScanGraph(const Message<msg::SubmapConstraint>& m, const SubmapConstraintInput& c);
  /// At stop: the scan-level optimisation; false when it could not run.
  bool optimizeScanGraph();
  void publishPoses(const std::map<int, tessera::Pose2>& poses, double chi2, int iterations);
  void publishComposedTrajectory();
  void writeGraph();

  GraphOptimizerActorOptions options_;
  SubmapGraph graph_;
  ScanGraph scan_graph_;
  SubmapTrimmer trimmer_;
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
  double optimize_seconds_ = 0.0, last_chi2_ = 0.0, trim_seconds_ = 0.0;
  std::uint64_t scan_rejected_ = 0, scan_composed_ = 0;
  double scan_seconds_ = 0.0, scan_chi2_ = 0.0;
  int scan_iterations_ = 0;
};

}  // namespace tessera::laser_slam
