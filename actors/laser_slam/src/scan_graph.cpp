#include <tessera/laser_slam/scan_graph.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tessera::laser_slam {
namespace {

Eigen::Vector3d vec(const tessera::Pose2& p) {
  return {p.x, p.y, p.theta};
}

tessera::Pose2 pose(const Eigen::Vector3d& v) {
  return {v.x(), v.y(), v.z()};
}

Eigen::Matrix3d diagonalInformation(double sigma_linear, double sigma_angular) {
  return Eigen::Vector3d(1.0 / (sigma_linear * sigma_linear), 1.0 / (sigma_linear * sigma_linear),
                         1.0 / (sigma_angular * sigma_angular))
      .asDiagonal();
}

}  // namespace

ScanGraph::ScanGraph(ScanGraphOptions options) : options_(std::move(options)) {
  auto positive = [](double v) { return std::isfinite(v) && v > 0; };
  if (options_.node_every < 1) throw std::invalid_argument("node_every must be >= 1");
  if (!positive(options_.intra_sigma_linear))
    throw std::invalid_argument("intra_sigma_linear must be > 0");
  if (!positive(options_.intra_sigma_angular))
    throw std::invalid_argument("intra_sigma_angular must be > 0");
  if (!(std::isfinite(options_.chain_sigma_linear) && options_.chain_sigma_linear >= 0))
    throw std::invalid_argument("chain_sigma_linear must be >= 0 (0 = no chain edges)");
  if (options_.chain_sigma_linear > 0 && !positive(options_.chain_sigma_angular))
    throw std::invalid_argument("chain_sigma_angular must be > 0 with chain edges");
  if (options_.stamp_tolerance_ns < 0)
    throw std::invalid_argument("stamp_tolerance_ns must be >= 0");
  if (const std::string e = pose_graph::optionsError(options_.optimizer); !e.empty())
    throw std::invalid_argument("optimizer." + e);
}

bool ScanGraph::checkCovariance(const Eigen::Matrix3d& cov, const std::string& what) {
  if (!cov.allFinite()) {
    last_error_ = what + " has a non-finite covariance";
    return false;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (cov + cov.transpose()));
  if (eig.eigenvalues().minCoeff() <= 0.0) {
    last_error_ = what + " has a covariance that is not positive definite";
    return false;
  }
  return true;
}

bool ScanGraph::addSubmap(int id, std::vector<StampedPose2> trajectory) {
  last_error_.clear();
  const std::string what = "submap " + std::to_string(id);
  if (trajectories_.count(id)) {
    last_error_ = what + " was added already";
    return false;
  }
  for (std::size_t i = 0; i < trajectory.size(); ++i) {
    if (!trajectory[i].pose.isFinite()) {
      last_error_ = what + ": scan " + std::to_string(i) + " has a non-finite pose";
      return false;
    }
    if (i > 0 && trajectory[i].stamp_ns <= trajectory[i - 1].stamp_ns) {
      last_error_ = what + ": scan stamps do not increase at scan " + std::to_string(i);
      return false;
    }
  }
  trajectories_[id].scans = std::move(trajectory);
  return true;
}

bool ScanGraph::addConstraint(const SubmapConstraintInput& c) {
  last_error_.clear();
  const std::string what = "constraint " + std::to_string(c.from) + " -> " + std::to_string(c.to);
  if (c.from == c.to) {
    last_error_ = what + " links a submap to itself";
    return false;
  }
  if (!c.relative.isFinite()) {
    last_error_ = what + " has a non-finite pose";
    return false;
  }
  if (!checkCovariance(c.covariance, what)) return false;
  constraints_.push_back(c);
  if (!c.revisit && c.lost) lost_starts_.insert(c.to);
  return true;
}

bool ScanGraph::addLoop(const ScanLoopInput& loop, const SubmapConstraintInput& fallback) {
  last_error_.clear();
  const std::string what = "closure of scan " + std::to_string(loop.stamp_ns) + " in submap " +
                           std::to_string(loop.matched);
  if (!loop.pose.isFinite()) {
    last_error_ = what + " has a non-finite pose";
    return false;
  }
  if (!checkCovariance(loop.covariance, what)) return false;
  loops_.push_back({loop, fallback});
  return true;
}

int ScanGraph::find(const Trajectory& t, std::int64_t stamp) const {
  const auto at = std::partition_point(t.scans.begin(), t.scans.end(), [&](const auto& s) {
    return s.stamp_ns < stamp - options_.stamp_tolerance_ns;
  });
  if (at == t.scans.end() || std::abs(at->stamp_ns - stamp) > options_.stamp_tolerance_ns)
    return -1;
  return static_cast<int>(at - t.scans.begin());
}

void ScanGraph::addScanNodes(int submap, Trajectory& t, const std::vector<std::int64_t>& closed,
                             std::map<std::int64_t, int>& node_by_stamp,
                             std::set<std::pair<int, int>>& sharing) {
  const int k = graph_.index(submap);
  const std::size_t n = t.scans.size();
  t.node_of.assign(n, -1);
  const Eigen::Matrix3d intra =
      diagonalInformation(options_.intra_sigma_linear, options_.intra_sigma_angular);
  const bool chain = options_.chain_sigma_linear > 0;
  const Eigen::Matrix3d chain_information =
      chain ? diagonalInformation(options_.chain_sigma_linear, options_.chain_sigma_angular)
            : Eigen::Matrix3d::Zero();
  const std::int64_t tol = options_.stamp_tolerance_ns;
  int previous = -1;  // index in t.scans of the previous node
  for (std::size_t i = 0; i < n; ++i) {
    const std::int64_t stamp = t.scans[i].stamp_ns;
    const auto c = std::lower_bound(closed.begin(), closed.end(), stamp - tol);
    const bool is_closed = c != closed.end() && *c <= stamp + tol;
    if (!(i % static_cast<std::size_t>(options_.node_every) == 0 || i + 1 == n || is_closed))
      continue;
    // The scan that ended the previous submap starts this one: one node, an edge from each;
    // not for a submap started lost, whose first scan gets a node of its own (the stamp keeps
    // naming the other's node).
    int node = -1;
    const auto same = node_by_stamp.lower_bound(stamp - tol);
    const bool taken = same != node_by_stamp.end() && same->first <= stamp + tol;
    if (taken && !lost_starts_.count(submap)) {
      node = same->second;
      // The node's own submap is the one whose intra edge made it: the first edge into it.
      for (const auto& e : graph_.edges)
        if (e.to == node && graph_.ids[static_cast<std::size_t>(e.from)] >= 0) {
          const int other = static_cast<int>(graph_.ids[static_cast<std::size_t>(e.from)]);
          sharing.emplace(std::min(other, submap), std::max(other, submap));
          break;
        }
    } else {
      const auto warm = taken ? warm_scans_.end() : warm_scans_.find(stamp);
      const Eigen::Vector3d initial =
          warm != warm_scans_.end() ? warm->second
                                    : pose_graph::compose(graph_.poses[static_cast<std::size_t>(k)],
                                                          vec(t.scans[i].pose));
      node = graph_.addNode(-1 - static_cast<std::int64_t>(scan_nodes_), initial);
      if (!taken) node_by_stamp.emplace(stamp, node);
      ++scan_nodes_;
    }
    t.node_of[i] = node;
    graph_.edges.push_back({k, node, vec(t.scans[i].pose), intra, false});
    if (chain && previous >= 0)
      graph_.edges.push_back(
          {t.node_of[static_cast<std::size_t>(previous)], node,
           vec(t.scans[static_cast<std::size_t>(previous)].pose.inverse() * t.scans[i].pose),
           chain_information, false});
    previous = static_cast<int>(i);
  }
}

pose_graph::OptimizerSummary ScanGraph::optimize(const std::map<int, tessera::Pose2>& start) {
  graph_ = pose_graph::Graph2D{};
  scan_nodes_ = loops_on_scans_ = loops_on_submaps_ = 0;
  // Submap nodes first, by id: the first one anchors the map frame.
  std::map<int, Eigen::Vector3d> origins;
  for (const auto& [id, p] : start)
    if (p.isFinite()) origins[id] = vec(p);
  for (const auto& [id, p] : warm_submaps_) origins[id] = p;
  for (const auto& [id, p] : origins) graph_.addNode(id, p);

  std::vector<std::int64_t> closed;
  for (const auto& l : loops_)
    if (graph_.contains(l.scan.matched)) closed.push_back(l.scan.stamp_ns);
  std::sort(closed.begin(), closed.end());
  std::map<std::int64_t, int> node_by_stamp;
  std::set<std::pair<int, int>> sharing;  // submaps (lower id first) with a shared scan node
  for (auto& [id, t] : trajectories_) {
    t.node_of.assign(t.scans.size(), -1);
    if (graph_.contains(id)) addScanNodes(id, t, closed, node_by_stamp, sharing);
  }

  std::vector<pose_graph::Edge2D> submap_edges;
  auto submapEdge = [&](const SubmapConstraintInput& c) {
    if (!graph_.contains(c.from) || !graph_.contains(c.to)) return;
    pose_graph::addOrFuse(
        graph_,
        {graph_.index(c.from), graph_.index(c.to), vec(c.relative),
         pose_graph::informationFromFrameCovariance(vec(c.relative), c.covariance), c.revisit});
  };
  for (const auto& c : constraints_)
    if (c.revisit || options_.shared_handovers ||
        !sharing.count({std::min(c.from, c.to), std::max(c.from, c.to)}))
      submapEdge(c);
  const std::int64_t tol = options_.stamp_tolerance_ns;
  for (const auto& l : loops_) {
    const auto node = node_by_stamp.lower_bound(l.scan.stamp_ns - tol);
    if (graph_.contains(l.scan.matched) && node != node_by_stamp.end() &&
        node->first <= l.scan.stamp_ns + tol) {
      graph_.edges.push_back(
          {graph_.index(l.scan.matched), node->second, vec(l.scan.pose),
           pose_graph::informationFromFrameCovariance(vec(l.scan.pose), l.scan.covariance), true});
      ++loops_on_scans_;
    } else if (graph_.contains(l.fallback.from) && graph_.contains(l.fallback.to)) {
      submapEdge(l.fallback);
      ++loops_on_submaps_;
    }
  }

  const pose_graph::OptimizerSummary summary = pose_graph::optimize(graph_, options_.optimizer);
  for (const auto& [id, p] : origins) warm_submaps_[id] = graph_.poses[graph_.index(id)];
  for (const auto& [stamp, node] : node_by_stamp)
    warm_scans_[stamp] = graph_.poses[static_cast<std::size_t>(node)];
  return summary;
}

std::map<int, tessera::Pose2> ScanGraph::submapPoses() const {
  std::map<int, tessera::Pose2> out;
  for (int i = 0; i < graph_.size(); ++i)
    if (graph_.ids[static_cast<std::size_t>(i)] >= 0)
      out[static_cast<int>(graph_.ids[static_cast<std::size_t>(i)])] =
          pose(graph_.poses[static_cast<std::size_t>(i)]);
  return out;
}

bool ScanGraph::scanPose(std::int64_t stamp_ns, tessera::Pose2& out) const {
  for (const auto& [id, t] : trajectories_) {
    const int i = find(t, stamp_ns);
    if (i < 0 || t.node_of.size() != t.scans.size()) continue;
    const auto at = static_cast<std::size_t>(i);
    if (t.node_of[at] >= 0) {
      out = pose(graph_.poses[static_cast<std::size_t>(t.node_of[at])]);
      return true;
    }
    // Between two nodes of its submap (the first and last scans are nodes when any is): each
    // carries the scan rigidly; blend the two by time so the correction changes smoothly.
    std::size_t a = at, b = at;
    while (a > 0 && t.node_of[a] < 0) --a;
    while (b + 1 < t.scans.size() && t.node_of[b] < 0) ++b;
    if (t.node_of[a] < 0 || t.node_of[b] < 0) continue;
    const tessera::Pose2& s = t.scans[at].pose;
    const tessera::Pose2 from_a = pose(graph_.poses[static_cast<std::size_t>(t.node_of[a])]) *
                                  (t.scans[a].pose.inverse() * s);
    const tessera::Pose2 from_b = pose(graph_.poses[static_cast<std::size_t>(t.node_of[b])]) *
                                  (t.scans[b].pose.inverse() * s);
    const double f = static_cast<double>(t.scans[at].stamp_ns - t.scans[a].stamp_ns) /
                     static_cast<double>(t.scans[b].stamp_ns - t.scans[a].stamp_ns);
    out = {from_a.x + f * (from_b.x - from_a.x), from_a.y + f * (from_b.y - from_a.y),
           from_a.theta + f * tessera::angleDiff(from_b.theta, from_a.theta)};
    return true;
  }
  return false;
}

}  // namespace tessera::laser_slam
