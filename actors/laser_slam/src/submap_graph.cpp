#include <tessera/laser_slam/submap_graph.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tessera::laser_slam {
namespace {

Eigen::Vector3d vec(const tessera::Pose2& p) {
  return {p.x, p.y, p.theta};
}

std::string describe(const SubmapConstraintInput& c) {
  return std::to_string(c.from) + " -> " + std::to_string(c.to);
}

}  // namespace

SubmapGraph::SubmapGraph(SubmapGraphOptions options) : options_(std::move(options)) {
  if (const std::string e = pose_graph::optionsError(options_.optimizer); !e.empty())
    throw std::invalid_argument("optimizer." + e);
  for (const auto& [key, value] :
       {std::pair{"closure_shared_std_linear", options_.closure_shared_std_linear},
        std::pair{"closure_shared_std_angular", options_.closure_shared_std_angular}})
    if (!(std::isfinite(value) && value >= 0.0))
      throw std::invalid_argument(std::string(key) + " must be finite and >= 0 (got " +
                                  std::to_string(value) + ")");
  if ((options_.closure_shared_std_linear > 0.0) != (options_.closure_shared_std_angular > 0.0))
    throw std::invalid_argument(
        "closure_shared_std_linear and closure_shared_std_angular are both 0 (off) or both > 0");
}

void SubmapGraph::addSubmap(int id, const tessera::Pose2& guess) {
  if (graph_.contains(id)) return;
  graph_.addNode(id, vec(guess));
  resolvePending();
}

SubmapGraph::Outcome SubmapGraph::addConstraint(const SubmapConstraintInput& c) {
  const Outcome outcome = insert(c);
  if (outcome == Outcome::kAdded || outcome == Outcome::kFused) resolvePending();
  return outcome;
}

SubmapGraph::Outcome SubmapGraph::insert(const SubmapConstraintInput& c) {
  last_error_.clear();
  if (c.from == c.to) {
    last_error_ = "constraint " + describe(c) + " links a submap to itself";
    return Outcome::kRejected;
  }
  if (!c.relative.isFinite() || !c.covariance.allFinite()) {
    last_error_ = "constraint " + describe(c) + " has a non-finite pose or covariance";
    return Outcome::kRejected;
  }
  const Eigen::Matrix3d cov = 0.5 * (c.covariance + c.covariance.transpose());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  if (eig.eigenvalues().minCoeff() <= 0.0) {
    last_error_ = "constraint " + describe(c) +
                  " has a covariance that is not positive definite (smallest eigenvalue " +
                  std::to_string(eig.eigenvalues().minCoeff()) + ")";
    return Outcome::kRejected;
  }
  if (removed(c.from) || removed(c.to)) {
    last_error_ = "constraint " + describe(c) + " names a submap removed from the map (lifelong)";
    return Outcome::kRejected;
  }
  const auto key = std::make_tuple(c.from, c.to, c.relative.x, c.relative.y, c.relative.theta);
  if (seen_.count(key)) return Outcome::kDuplicate;

  const bool from_known = graph_.contains(c.from), to_known = graph_.contains(c.to);
  if (!from_known || (!to_known && c.revisit)) {
    if (pending_.size() >= options_.max_pending) {
      last_error_ = "more than " + std::to_string(options_.max_pending) +
                    " constraints wait for unknown submaps; dropped the oldest, " +
                    describe(pending_.front());
      pending_.erase(pending_.begin());
    }
    pending_.push_back(c);
    return Outcome::kPending;
  }
  seen_.insert(key);
  seen_order_.push_back(key);
  if (seen_order_.size() > kMaxSeen) {
    seen_.erase(seen_order_.front());
    seen_order_.pop_front();
  }
  const int a = graph_.index(c.from);
  const Eigen::Vector3d placed = pose_graph::compose(graph_.poses[a], vec(c.relative));
  if (!to_known) graph_.addNode(c.to, placed);
  const int b = graph_.index(c.to);
  auto isolated = [this](int n) {
    return std::none_of(graph_.edges.begin(), graph_.edges.end(),
                        [n](const auto& e) { return e.from == n || e.to == n; });
  };
  // The first edge of a submap places it by composition: that is its optimum and nothing else
  // moves. Node 0 anchors the map frame and is never the one moved. A fusion, or an edge
  // between two linked submaps, can move everything: that needs an optimisation.
  bool placed_by_composition = true;
  if (isolated(b) && b != 0) {
    graph_.poses[b] = placed;
  } else if (isolated(a) && a != 0) {
    graph_.poses[a] = pose_graph::compose(graph_.poses[b], pose_graph::inverse(vec(c.relative)));
  } else {
    placed_by_composition = false;
  }
  const pose_graph::Edge2D edge{a, b, vec(c.relative),
                                pose_graph::informationFromFrameCovariance(vec(c.relative), cov),
                                c.revisit};
  const bool scan_match = c.revisit && c.scan_match;
  const bool tracked = options_.closure_shared_std_linear > 0.0 &&
                       (scan_match || pair_parts_.count(std::minmax(c.from, c.to)));
  const bool fused =
      tracked ? fuseIntoPair(edge, c.from, c.to, scan_match) : pose_graph::addOrFuse(graph_, edge);
  if (!placed_by_composition) dirty_ = true;
  return fused ? Outcome::kFused : Outcome::kAdded;
}

bool SubmapGraph::fuseIntoPair(const pose_graph::Edge2D& edge, int from_id, int to_id,
                               bool scan_match) {
  using pose_graph::Measurement2D;
  const bool forward = from_id < to_id;
  const std::pair<int, int> key = std::minmax(from_id, to_id);
  const int lo = graph_.index(key.first), hi = graph_.index(key.second);
  auto orient = [](const Measurement2D& m, bool keep) { return keep ? m : pose_graph::invert(m); };
  const auto existing = std::find_if(graph_.edges.begin(), graph_.edges.end(), [&](const auto& e) {
    return (e.from == lo && e.to == hi) || (e.from == hi && e.to == lo);
  });
  const Measurement2D incoming = orient({edge.measurement, edge.information}, forward);
  auto parts = pair_parts_.find(key);
  if (parts == pair_parts_.end()) {
    // The pair's first scan match (insert() sends nothing else here for an untracked pair). An
    // edge already there (a hand-over, a camera revisit, a marginalisation) is all "others".
    PairParts fresh{incoming, std::nullopt};
    if (existing != graph_.edges.end())
      fresh.others = orient({existing->measurement, existing->information}, existing->from == lo);
    parts = pair_parts_.emplace(key, fresh).first;
  } else if (scan_match) {
    parts->second.scan_matches = pose_graph::fuse(parts->second.scan_matches, incoming);
  } else {
    auto& others = parts->second.others;
    others = others ? pose_graph::fuse(*others, incoming) : incoming;
  }
  // The matches' part: independent errors fused, then the shared one added (isotropic in
  // (x, y), so the same in every frame and added in the edge's chart as it is).
  const double sl = options_.closure_shared_std_linear, sa = options_.closure_shared_std_angular;
  const Measurement2D& matches = parts->second.scan_matches;
  const Eigen::Matrix3d cov =
      Eigen::Vector3d(sl * sl, sl * sl, sa * sa).asDiagonal().toDenseMatrix() +
      matches.information.inverse();
  Measurement2D together{matches.mean, cov.inverse()};
  together.information = 0.5 * (together.information + together.information.transpose()).eval();
  if (parts->second.others) together = pose_graph::fuse(*parts->second.others, together);
  if (existing == graph_.edges.end()) {
    graph_.edges.push_back({lo, hi, together.mean, together.information, edge.robust});
    return false;
  }
  const Measurement2D stored = orient(together, existing->from == lo);
  existing->measurement = stored.mean;
  existing->information = stored.information;
  existing->robust = existing->robust || edge.robust;
  return true;
}

void SubmapGraph::resolvePending() {
  // Each placement can unblock others (a chain of hand-overs arriving backwards).
  bool progress = true;
  while (progress && !pending_.empty()) {
    progress = false;
    for (std::size_t k = 0; k < pending_.size(); ++k) {
      const auto& c = pending_[k];
      if (!graph_.contains(c.from) || (c.revisit && !graph_.contains(c.to))) continue;
      const SubmapConstraintInput ready = c;
      pending_.erase(pending_.begin() + static_cast<std::ptrdiff_t>(k));
      insert(ready);
      progress = true;
      break;
    }
  }
}

bool SubmapGraph::removeSubmap(int id) {
  last_error_.clear();
  if (!graph_.contains(id)) {
    last_error_ = "submap " + std::to_string(id) + " is not in the graph";
    return false;
  }
  if (graph_.index(id) == 0) {
    last_error_ = "submap " + std::to_string(id) + " anchors the map frame";
    return false;
  }
  pose_graph::marginalizeNode(graph_, id);
  // Marginalising rewrote edges between the neighbours: their parts start again from the edges.
  pair_parts_.clear();
  removed_.insert(id);
  std::erase_if(pending_,
                [id](const SubmapConstraintInput& c) { return c.from == id || c.to == id; });
  dirty_ = true;
  return true;
}

pose_graph::OptimizerSummary SubmapGraph::optimize() {
  dirty_ = false;
  return pose_graph::optimize(graph_, options_.optimizer);
}

tessera::Pose2 SubmapGraph::pose(int id) const {
  const auto& p = graph_.poses[graph_.index(id)];
  return {p.x(), p.y(), p.z()};
}

std::map<int, tessera::Pose2> SubmapGraph::poses() const {
  std::map<int, tessera::Pose2> out;
  for (int i = 0; i < graph_.size(); ++i) {
    const auto& p = graph_.poses[i];
    out[static_cast<int>(graph_.ids[i])] = {p.x(), p.y(), p.z()};
  }
  return out;
}

std::vector<std::string> SubmapGraph::pendingDescriptions() const {
  std::vector<std::string> out;
  for (const auto& c : pending_) out.push_back(describe(c));
  return out;
}

}  // namespace tessera::laser_slam
