#include <tessera/laser_slam/graph_optimizer_actor.hpp>

#include <tessera/actor_common/map_message.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/pose_graph/pose_graph_io.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <set>
#include <stdexcept>

namespace tessera::laser_slam {
namespace {

/// A core graph built from its options group; the core's complaint names the key inside the
/// group, the error the full key.
template <class Graph, class Options>
Graph checkedGraph(const char* group, const Options& options) {
  try {
    return Graph(options);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(std::string("graph_optimizer: ") + group + "." + e.what());
  }
}

}  // namespace

GraphOptimizerActor::GraphOptimizerActor(GraphOptimizerActorOptions options)
    : options_(std::move(options)),
      graph_(checkedGraph<SubmapGraph>("graph", options_.graph)),
      scan_graph_(checkedGraph<ScanGraph>("scan_graph", options_.scan_graph.options)),
      trimmer_(checkedGraph<SubmapTrimmer>("lifelong", options_.lifelong.trimmer)) {
  if (options_.frame_id.empty()) throw ConfigError("graph_optimizer: frame_id must not be empty");
  if (options_.lifelong.enabled && options_.scan_graph.enabled)
    throw ConfigError(
        "graph_optimizer: lifelong.enabled and scan_graph.enabled cannot both be true: the scan "
        "graph keeps every scan of every submap, which lifelong mapping must not");
  if (options_.lifelong.enabled && options_.compose_trajectory)
    throw ConfigError(
        "graph_optimizer: lifelong.enabled and compose_trajectory cannot both be true: the "
        "composed trajectory keeps every pose and needs the trimmed submaps");
}

void GraphOptimizerActor::configure(ActorContext& ctx) {
  output_dir_ = ctx.outputDir();
  ctx.subscribe<msg::Submap>("submaps", MailboxPolicy::reliable(),
                             [this](const Message<msg::Submap>& m) { onSubmap(m); });
  ctx.subscribe<msg::SubmapConstraint>(
      "constraints", MailboxPolicy::reliable(),
      [this](const Message<msg::SubmapConstraint>& m) { onConstraint(m); });
  poses_pub_ = ctx.advertise<msg::SubmapPoses>("submap_poses");
  if (options_.compose_trajectory) {
    ctx.subscribe<msg::PoseStamped>("trajectory", MailboxPolicy::reliable(),
                                    [this](const Message<msg::PoseStamped>& m) {
                                      const tessera::Pose2 p = toPose2(m->getPose());
                                      if (p.isFinite())
                                        trajectory_.emplace_back(m->getHeader().getStampNs(), p);
                                    });
    trajectory_pub_ = ctx.advertise<msg::PoseStamped>("trajectory_final");
  }
}

void GraphOptimizerActor::onSubmap(const Message<msg::Submap>& m) {
  ++submaps_;
  last_stamp_ = std::max(last_stamp_, m->getHeader().getStampNs());
  const tessera::Pose2 guess = toPose2(m->getGlobalPose());
  if (guess.isFinite()) spans_[static_cast<int>(m->getId())] = {m->getHeader().getStampNs(), guess};
  // A non-finite guess is harmless only if a constraint places the submap: start it at the
  // origin and let the constraints move it.
  graph_.addSubmap(static_cast<int>(m->getId()), guess.isFinite() ? guess : tessera::Pose2{});
  if (options_.scan_graph.enabled && m->getFinished() && m->getTrajectory().size() > 0) {
    std::vector<StampedPose2> trajectory;
    trajectory.reserve(m->getTrajectory().size());
    for (const auto p : m->getTrajectory())
      trajectory.push_back({p.getStampNs(), {p.getX(), p.getY(), p.getTheta()}});
    if (!scan_graph_.addSubmap(static_cast<int>(m->getId()), std::move(trajectory))) {
      std::cerr << "[graph_optimizer] scan graph: " << scan_graph_.lastError()
                << "; its scans are moved with the submap\n";
      ++scan_rejected_;
    }
  }
  if (options_.lifelong.enabled && m->getFinished()) {
    try {
      trimmer_.addSubmap(static_cast<int>(m->getId()),
                         trimmer_.footprint(toOccupancyMap(m->getGrid())));
    } catch (const std::invalid_argument& e) {
      // Kept, never trimmed: without its cells nothing says what it covers.
      std::cerr << "[graph_optimizer] lifelong: submap " << m->getId() << " grid: " << e.what()
                << "; it is never trimmed\n";
    }
    trimCovered();
  }
  if (graph_.needsOptimization()) optimizeAndPublish();
}

void GraphOptimizerActor::trimCovered() {
  if (graph_.nodes() == 0) return;
  const auto t0 = std::chrono::steady_clock::now();
  const std::set<int> keep = {static_cast<int>(graph_.graph().ids.front())};  // the anchor
  for (const int id : trimmer_.trim(graph_.poses(), keep)) {
    if (graph_.removeSubmap(id))
      spans_.erase(id);
    else
      std::cerr << "[graph_optimizer] lifelong: " << graph_.lastError() << "; not trimmed\n";
  }
  trim_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void GraphOptimizerActor::onConstraint(const Message<msg::SubmapConstraint>& m) {
  ++constraints_;
  last_stamp_ = std::max(last_stamp_, m->getHeader().getStampNs());
  SubmapConstraintInput c;
  c.from = static_cast<int>(m->getFromId());
  c.to = static_cast<int>(m->getToId());
  c.relative = toPose2(m->getRelative());
  c.revisit = m->getKind() == msg::SubmapConstraint::Kind::REVISIT;
  c.lost = !c.revisit && m->getLost();
  c.scan_match = c.revisit && m->hasScanInTo();
  if (!readCovariance(m->getRelative(), c.covariance)) {
    std::cerr << "[graph_optimizer] constraint " << c.from << " -> " << c.to
              << " has no covariance (9 values expected); rejected\n";
    ++rejected_;
    return;
  }
  const SubmapGraph::Outcome outcome = graph_.addConstraint(c);
  switch (outcome) {
    case SubmapGraph::Outcome::kAdded:
      ++added_;
      break;
    case SubmapGraph::Outcome::kFused:
      ++fused_;
      break;
    case SubmapGraph::Outcome::kDuplicate:
      ++duplicates_;
      break;
    case SubmapGraph::Outcome::kPending:
      break;
    case SubmapGraph::Outcome::kRejected:
      std::cerr << "[graph_optimizer] " << graph_.lastError() << "; rejected\n";
      ++rejected_;
      return;
  }
  if (!graph_.lastError().empty()) std::cerr << "[graph_optimizer] " << graph_.lastError() << "\n";
  if (options_.scan_graph.enabled && outcome != SubmapGraph::Outcome::kDuplicate)
    addToScanGraph(m, c);
  if (graph_.needsOptimization()) optimizeAndPublish();
}

void GraphOptimizerActor::addToScanGraph(const Message<msg::SubmapConstraint>& m,
                                         const SubmapConstraintInput& c) {
  // Exact repeats were counted as duplicates and are not passed here.
  bool ok = true;
  if (c.scan_match) {
    ScanLoopInput loop;
    loop.matched = c.to;
    loop.stamp_ns = m->getHeader().getStampNs();
    loop.pose = toPose2(m->getScanInTo());
    if (readCovariance(m->getScanInTo(), loop.covariance)) {
      ok = scan_graph_.addLoop(loop, c);
    } else {
      std::cerr << "[graph_optimizer] constraint " << c.from << " -> " << c.to
                << ": scanInTo has no covariance (9 values expected); kept between submaps\n";
      ++scan_rejected_;
      ok = scan_graph_.addConstraint(c);
    }
  } else {
    ok = scan_graph_.addConstraint(c);
  }
  if (!ok) {
    std::cerr << "[graph_optimizer] scan graph: " << scan_graph_.lastError() << "; left out\n";
    ++scan_rejected_;
  }
}

void GraphOptimizerActor::optimizeAndPublish() {
  try {
    const auto s = graph_.optimize();
    ++optimizations_;
    optimize_seconds_ += s.seconds;
    last_chi2_ = s.final_chi2;
    publishPoses(graph_.poses(), s.final_chi2, s.iterations);
  } catch (const pose_graph::GraphError& e) {
    // Keep the last good poses; the next constraint tries again.
    std::cerr << "[graph_optimizer] optimisation failed: " << e.what() << "\n";
    ++solver_failures_;
  }
}

void GraphOptimizerActor::publishPoses(const std::map<int, tessera::Pose2>& poses, double chi2,
                                       int iterations) {
  const std::set<int>& trimmed = graph_.removedSubmaps();
  auto loan = poses_pub_.loan(64 * poses.size() + 4 * trimmed.size() + 256);
  setHeader(loan->initHeader(), last_stamp_, options_.frame_id, poses_pub_.nextSeq());
  auto list = loan->initPoses(static_cast<unsigned>(poses.size()));
  unsigned k = 0;
  for (const auto& [id, p] : poses) {
    list[k].setId(static_cast<std::uint32_t>(id));
    writePose(list[k].initPose(), tessera::Pose2{p.x, p.y, p.theta});
    ++k;
  }
  loan->setChi2(chi2);
  loan->setIterations(static_cast<std::uint32_t>(std::max(0, iterations)));
  if (!trimmed.empty()) {
    auto list_out = loan->initTrimmed(static_cast<unsigned>(trimmed.size()));
    unsigned i = 0;
    for (const int id : trimmed) list_out.set(i++, static_cast<std::uint32_t>(id));
  }
  poses_pub_.publish(std::move(loan));
  ++published_;
}

void GraphOptimizerActor::stop() {
  for (const auto& d : graph_.pendingDescriptions())
    std::cerr << "[graph_optimizer] constraint " << d
              << " names a submap that never arrived; left out of the graph\n";
  if (graph_.needsOptimization()) optimizeAndPublish();
  if (options_.scan_graph.enabled && graph_.nodes() > 0 && optimizeScanGraph())
    publishPoses(scan_graph_.submapPoses(), scan_chi2_, 0);
  else if (graph_.nodes() > 0)
    publishPoses(graph_.poses(), graph_.chi2(), 0);
  if (options_.compose_trajectory) publishComposedTrajectory();
  if (!options_.g2o_file.empty() && !output_dir_.empty() && graph_.nodes() > 0) writeGraph();
}

bool GraphOptimizerActor::optimizeScanGraph() {
  try {
    const auto s = scan_graph_.optimize(graph_.poses());
    scan_seconds_ = s.seconds;
    scan_chi2_ = s.final_chi2;
    scan_iterations_ = s.iterations;
    scan_optimized_ = true;
  } catch (const pose_graph::GraphError& e) {
    // stop() must not throw: the submap-level result stands.
    std::cerr << "[graph_optimizer] scan-level optimisation failed: " << e.what()
              << "; the final poses are the submap-level ones\n";
    ++solver_failures_;
  }
  return scan_optimized_;
}

void GraphOptimizerActor::writeGraph() {
  // The solvers hold the first node where it is (it anchors the map frame): say so in the file.
  pose_graph::Graph2D out = graph_.graph();
  if (out.size() > 0) out.fixed[0] = true;
  // stop() must not throw: a failed write is logged and reported in the summary.
  try {
    const std::filesystem::path path = std::filesystem::path(output_dir_) / options_.g2o_file;
    pose_graph::writeG2o(out, path);
    graph_path_ = path.string();
  } catch (const std::exception& e) {
    write_error_ = e.what();
    std::cerr << "[graph_optimizer] " << write_error_ << "\n";
  }
}

void GraphOptimizerActor::publishComposedTrajectory() {
  const std::map<int, tessera::Pose2> origins =
      scan_optimized_ ? scan_graph_.submapPoses() : graph_.poses();
  // Submaps by their last scan's stamp: a pose belongs to the first one not older than it.
  std::map<Nanos, int> by_end;
  for (const auto& [id, span] : spans_)
    if (origins.count(id)) by_end.emplace(span.last_stamp, id);
  if (by_end.empty()) return;
  std::sort(trajectory_.begin(), trajectory_.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& [stamp, pose] : trajectory_) {
    tessera::Pose2 moved;
    if (!scan_optimized_ || !scan_graph_.scanPose(stamp, moved)) {
      auto it = by_end.lower_bound(stamp);
      if (it == by_end.end()) --it;  // after the last submap's last scan: still the last submap
      const int id = it->second;
      moved = origins.at(id) * (spans_.at(id).chained.inverse() * pose);
      if (scan_optimized_) ++scan_composed_;
    }
    auto loan = trajectory_pub_.loan();
    setHeader(loan->initHeader(), stamp, options_.frame_id, trajectory_pub_.nextSeq());
    writePose(loan->initPose(), tessera::Pose2{moved.x, moved.y, moved.theta});
    trajectory_pub_.publish(std::move(loan));
  }
}

void GraphOptimizerActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["graph_nodes"] = i64(graph_.nodes());
  out["graph_edges"] = i64(graph_.edges());
  out["submaps_received"] = i64(submaps_);
  out["constraints_received"] = i64(constraints_);
  out["constraints_added"] = i64(added_);
  out["constraints_fused"] = i64(fused_);
  out["constraints_duplicate"] = i64(duplicates_);
  out["constraints_rejected"] = i64(rejected_);
  out["constraints_unresolved"] = i64(graph_.pending());
  out["optimizations"] = i64(optimizations_);
  out["optimize_s"] = optimize_seconds_;
  out["final_chi2"] = last_chi2_;
  if (solver_failures_ > 0) out["solver_failures"] = i64(solver_failures_);
  if (options_.lifelong.enabled) {
    out["submaps_trimmed"] = i64(graph_.removedSubmaps().size());
    out["trimmer_submaps"] = i64(trimmer_.size());
    out["trimmer_points"] = i64(trimmer_.points());
    out["trim_s"] = trim_seconds_;
  }
  if (options_.scan_graph.enabled) {
    out["scan_graph_optimized"] = std::int64_t{scan_optimized_ ? 1 : 0};
    out["scan_graph_nodes"] = i64(scan_graph_.nodes());
    out["scan_graph_scan_nodes"] = i64(scan_graph_.scanNodes());
    out["scan_graph_edges"] = i64(scan_graph_.edges());
    out["scan_graph_loops_on_scans"] = i64(scan_graph_.loopsOnScans());
    out["scan_graph_loops_on_submaps"] = i64(scan_graph_.loopsOnSubmaps());
    out["scan_graph_rejected"] = i64(scan_rejected_);
    out["scan_graph_poses_composed"] = i64(scan_composed_);
    out["scan_graph_s"] = scan_seconds_;
    out["scan_graph_chi2"] = scan_chi2_;
    out["scan_graph_iterations"] = std::int64_t{scan_iterations_};
  }
  if (!graph_path_.empty()) out["graph_path"] = graph_path_;
  if (!write_error_.empty()) out["graph_write_error"] = write_error_;
}

TESSERA_REGISTER_ACTOR("graph_optimizer", GraphOptimizerActor, GraphOptimizerActorOptions,
                       "global laser SLAM: fuses submap constraints and optimises the pose graph");

}  // namespace tessera::laser_slam
