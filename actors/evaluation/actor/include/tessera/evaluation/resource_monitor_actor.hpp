// resource_monitor actor: this process's memory and CPU over a run, sampled on the run's own
// clock, for soak tests (`tessera bench soak`, docs/architecture.md#lifelong-operation). Every
// period_s of run time (simulated or wall, as the profile's clock) and once at stop it appends a
// row to `file` in the output folder (CSV, written to a temporary file, renamed at stop):
//   t_s        run time since the first sample [s]
//   rss_mb     resident memory now [MiB] (not the peak: a soak test asks whether it stays flat)
//   cpu_s      process CPU time so far (every thread, user + system) [s]
//   scans      scans received so far on `scan`
//   submaps    submaps made so far (the largest id in submap_poses + 1)
//   graph_nodes submaps in the latest optimised graph (what lifelong mapping keeps bounded)
//   trimmed    submaps lifelong mapping removed so far
// With keyframes: true (an RGB-D profile) the last three count keyframes instead: made (the
// largest id in keyframe_poses + 1), in the graph, and the rest (trimmed, or rejected).
// Subscribes:
//   scan            msg::LaserScan      reliable       counted (the handler only counts)
//   submap_poses    msg::SubmapPoses    keep_latest(1) with graph: true, the graph's size
//   keyframe_poses  msg::KeyframePoses  keep_latest(1) with keyframes: true, likewise
// Nothing is published. Without an output folder nothing is written; the summary still has
// the last row's figures.
#pragma once

#include <tessera/runtime/actor.hpp>

#include <cstdint>
#include <memory>
#include <string>

namespace tessera::io {
class AtomicFile;
}

namespace tessera::evaluation {

struct ResourceMonitorOptions {
  double period_s = 3600.0;
  std::string file = "resources.csv";
  bool graph = true;
  bool keyframes = false;

  template <class V>
  void visit(V& v) {
    v("period_s", period_s, "[s of run time] between rows (> 0)");
    v("file", file, "CSV written in the output folder");
    v("graph", graph, "subscribe to submap_poses for the submap and graph-node counts");
    v("keyframes", keyframes,
      "subscribe to keyframe_poses instead: the counts are of keyframes (RGB-D profiles)");
  }
};

class ResourceMonitorActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit ResourceMonitorActor(ResourceMonitorOptions options);
  ~ResourceMonitorActor() override;
  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  void summarize(Summary& out) const override;

 private:
  void sample();

  ResourceMonitorOptions options_;
  ActorContext* ctx_ = nullptr;
  std::unique_ptr<io::AtomicFile> file_;
  std::string path_, error_;
  Nanos first_ = 0;
  std::uint64_t scans_ = 0, submaps_ = 0, graph_nodes_ = 0, trimmed_ = 0, rows_ = 0;
  double rss_mb_ = 0.0, cpu_s_ = 0.0;
};

}  // namespace tessera::evaluation
