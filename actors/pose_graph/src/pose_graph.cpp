#include <tessera/pose_graph/pose_graph.hpp>

#include <tessera/geometry/pose2.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <deque>
#include <map>
#include <numbers>
#include <sstream>

namespace tessera::pose_graph {
namespace {

template <class Matrix>
bool symmetricPsd(const Matrix& m) {
  if (!m.allFinite()) return false;
  if ((m - m.transpose()).cwiseAbs().maxCoeff() > 1e-9 * std::max(1.0, m.cwiseAbs().maxCoeff()))
    return false;
  Eigen::SelfAdjointEigenSolver<Matrix> eig(m, Eigen::EigenvaluesOnly);
  const double largest = eig.eigenvalues().cwiseAbs().maxCoeff();
  return eig.eigenvalues().minCoeff() >= -1e-9 * largest;
}

bool finite(const Eigen::Vector3d& p) {
  return p.allFinite();
}
bool finite(const Pose3& p) {
  return p.t.allFinite() && p.q.coeffs().allFinite();
}

template <class G>
void validateGraph(const G& graph) {
  if (graph.ids.size() != graph.poses.size() || graph.fixed.size() != graph.poses.size())
    throw GraphError("pose graph: ids, poses and fixed flags differ in length");
  for (int i = 0; i < graph.size(); ++i)
    if (!finite(graph.poses[i]))
      throw GraphError("pose graph: node " + std::to_string(graph.ids[i]) +
                       " has a non-finite pose");
  for (std::size_t k = 0; k < graph.edges.size(); ++k) {
    const auto& e = graph.edges[k];
    std::ostringstream where;
    where << "pose graph: edge " << k;
    if (e.from < 0 || e.from >= graph.size() || e.to < 0 || e.to >= graph.size())
      throw GraphError(where.str() + " names a node index outside [0, " +
                       std::to_string(graph.size()) + ")");
    where << " (" << graph.ids[e.from] << " -> " << graph.ids[e.to] << ")";
    if (e.from == e.to) throw GraphError(where.str() + " connects a node to itself");
    if (!finite(e.measurement)) throw GraphError(where.str() + " has a non-finite measurement");
    if (!symmetricPsd(e.information))
      throw GraphError(where.str() +
                       " has an information matrix that is not symmetric positive semidefinite");
  }
}

template <class G>
double chi2Of(const G& graph) {
  double sum = 0.0;
  for (const auto& e : graph.edges) {
    const auto err = edgeError(graph, e);
    sum += err.dot(e.information * err);
  }
  return sum;
}

// Chains i -> i+1 first (the odometry), then walks any edge from placed nodes.
template <class G, class Compose, class Invert>
void initializeByWalking(G& graph, Compose compose_fn, Invert invert_fn) {
  const int n = graph.size();
  if (n == 0) return;
  std::vector<std::vector<int>> incident(n);
  for (int k = 0; k < static_cast<int>(graph.edges.size()); ++k) {
    incident[graph.edges[k].from].push_back(k);
    incident[graph.edges[k].to].push_back(k);
  }
  std::vector<bool> placed(n, false);
  placed[0] = true;
  auto placeFrom = [&](int k, int known) {
    const auto& e = graph.edges[k];
    const int other = e.from == known ? e.to : e.from;
    graph.poses[other] = e.from == known ? compose_fn(graph.poses[known], e.measurement)
                                         : compose_fn(graph.poses[known], invert_fn(e.measurement));
    placed[other] = true;
    return other;
  };
  for (int i = 0; i + 1 < n; ++i) {
    if (!placed[i]) break;
    for (int k : incident[i]) {
      const auto& e = graph.edges[k];
      if ((e.from == i && e.to == i + 1) || (e.from == i + 1 && e.to == i)) {
        placeFrom(k, i);
        break;
      }
    }
  }
  std::deque<int> queue;
  for (int i = 0; i < n; ++i)
    if (placed[i]) queue.push_back(i);
  while (!queue.empty()) {
    const int i = queue.front();
    queue.pop_front();
    for (int k : incident[i]) {
      const auto& e = graph.edges[k];
      const int other = e.from == i ? e.to : e.from;
      if (!placed[other]) queue.push_back(placeFrom(k, i));
    }
  }
  for (int i = 0; i < n; ++i)
    if (!placed[i])
      throw GraphError("pose graph: node " + std::to_string(graph.ids[i]) +
                       " is not connected to node " + std::to_string(graph.ids[0]));
}

}  // namespace

template <class Pose, int Dim>
int Graph<Pose, Dim>::addNode(std::int64_t id, const Pose& pose, bool is_fixed) {
  if (!index_.emplace(id, size()).second)
    throw GraphError("pose graph: node " + std::to_string(id) + " added twice");
  ids.push_back(id);
  poses.push_back(pose);
  fixed.push_back(is_fixed);
  return size() - 1;
}

template <class Pose, int Dim>
int Graph<Pose, Dim>::index(std::int64_t id) const {
  const auto it = index_.find(id);
  if (it == index_.end()) throw GraphError("pose graph: no node with id " + std::to_string(id));
  return it->second;
}

template <class Pose, int Dim>
void Graph<Pose, Dim>::removeNode(std::int64_t id) {
  const int k = index(id);
  ids.erase(ids.begin() + k);
  poses.erase(poses.begin() + k);
  fixed.erase(fixed.begin() + k);
  std::erase_if(edges, [k](const EdgeType& e) { return e.from == k || e.to == k; });
  for (auto& e : edges) {
    if (e.from > k) --e.from;
    if (e.to > k) --e.to;
  }
  index_.erase(id);
  for (auto& [other, i] : index_)
    if (i > k) --i;
}

template struct Graph<Eigen::Vector3d, 3>;
template struct Graph<Pose3, 6>;

Eigen::Vector3d compose(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const double c = std::cos(a.z()), s = std::sin(a.z());
  return {a.x() + c * b.x() - s * b.y(), a.y() + s * b.x() + c * b.y(),
          normalizeAngle(a.z() + b.z())};
}

Eigen::Vector3d inverse(const Eigen::Vector3d& a) {
  const double c = std::cos(a.z()), s = std::sin(a.z());
  return {-c * a.x() - s * a.y(), s * a.x() - c * a.y(), normalizeAngle(-a.z())};
}

Eigen::Vector3d between(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const double c = std::cos(a.z()), s = std::sin(a.z());
  const double dx = b.x() - a.x(), dy = b.y() - a.y();
  return {c * dx + s * dy, -s * dx + c * dy, normalizeAngle(b.z() - a.z())};
}

Eigen::Vector3d edgeError(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                          const Eigen::Vector3d& measurement) {
  return between(measurement, between(a, b));
}

Eigen::Matrix<double, 6, 1> edgeError(const Pose3& a, const Pose3& b, const Pose3& measurement) {
  const Pose3 delta = measurement.inverse() * (a.inverse() * b);
  Eigen::Matrix<double, 6, 1> e;
  e.head<3>() = delta.t;
  e.tail<3>() = delta.q.w() < 0.0 ? Eigen::Vector3d(-delta.q.vec()) : delta.q.vec();
  return e;
}

Eigen::Vector3d edgeError(const Graph2D& graph, const Edge2D& edge) {
  return edgeError(graph.poses[edge.from], graph.poses[edge.to], edge.measurement);
}

Eigen::Matrix<double, 6, 1> edgeError(const Graph3D& graph, const Edge3D& edge) {
  return edgeError(graph.poses[edge.from], graph.poses[edge.to], edge.measurement);
}

double chi2(const Graph2D& graph) {
  return chi2Of(graph);
}
double chi2(const Graph3D& graph) {
  return chi2Of(graph);
}
void validate(const Graph2D& graph) {
  validateGraph(graph);
}
void validate(const Graph3D& graph) {
  validateGraph(graph);
}

Measurement2D fuse(const Measurement2D& first, const Measurement2D& second) {
  Eigen::Vector3d z2 = second.mean;
  z2.z() = first.mean.z() + normalizeAngle(z2.z() - first.mean.z());
  Measurement2D out;
  out.information = first.information + second.information;
  out.mean = out.information.ldlt().solve(first.information * first.mean + second.information * z2);
  out.mean.z() = normalizeAngle(out.mean.z());
  return out;
}

Measurement2D invert(const Measurement2D& m) {
  // inv(t, θ) = (−R(θ)ᵀ t, −θ); J is its Jacobian, and Ω' = J⁻ᵀ Ω J⁻¹.
  const double c = std::cos(m.mean.z()), s = std::sin(m.mean.z());
  const double x = m.mean.x(), y = m.mean.y();
  Eigen::Matrix3d J;
  J << -c, -s, s * x - c * y,  //
      s, -c, c * x + s * y,    //
      0, 0, -1;
  const Eigen::Matrix3d Jinv = J.inverse();
  Measurement2D out;
  out.mean = inverse(m.mean);
  out.information = Jinv.transpose() * m.information * Jinv;
  out.information = 0.5 * (out.information + out.information.transpose()).eval();
  return out;
}

Measurement2D chain(const Measurement2D& a_to_x, const Measurement2D& x_to_b) {
  const Eigen::Vector3d& p = a_to_x.mean;
  const Eigen::Vector3d& q = x_to_b.mean;
  const double c = std::cos(p.z()), s = std::sin(p.z());
  Eigen::Matrix3d jp, jq;              // d(p ⊕ q)/dp and d(p ⊕ q)/dq
  jp << 1, 0, -s * q.x() - c * q.y(),  //
      0, 1, c * q.x() - s * q.y(),     //
      0, 0, 1;
  jq << c, -s, 0,  //
      s, c, 0,     //
      0, 0, 1;
  const Eigen::Matrix3d cov = jp * a_to_x.information.inverse() * jp.transpose() +
                              jq * x_to_b.information.inverse() * jq.transpose();
  Measurement2D out;
  out.mean = compose(p, q);
  out.information = cov.inverse();
  out.information = 0.5 * (out.information + out.information.transpose()).eval();
  return out;
}

void marginalizeNode(Graph2D& graph, std::int64_t id) {
  const int x = graph.index(id);
  if (x == 0)
    throw GraphError("pose graph: node " + std::to_string(id) +
                     " anchors the frame (index 0) and cannot be marginalised");
  // Every edge at x as a measurement x -> neighbour.
  struct Tie {
    int node = 0;
    Measurement2D from_x;
    bool robust = false;
  };
  std::vector<Tie> ties;
  for (const auto& e : graph.edges) {
    if (e.from == x)
      ties.push_back({e.to, {e.measurement, e.information}, e.robust});
    else if (e.to == x)
      ties.push_back({e.from, invert({e.measurement, e.information}), e.robust});
  }
  std::vector<Edge2D> chained;
  if (ties.size() > 1) {
    const auto hub = std::max_element(ties.begin(), ties.end(), [](const Tie& a, const Tie& b) {
      return a.from_x.information.determinant() < b.from_x.information.determinant();
    });
    const Measurement2D hub_to_x = invert(hub->from_x);
    for (const auto& t : ties) {
      if (&t == &*hub || t.node == hub->node) continue;
      const Measurement2D m = chain(hub_to_x, t.from_x);
      chained.push_back({hub->node, t.node, m.mean, m.information, hub->robust || t.robust});
    }
  }
  graph.removeNode(id);
  for (auto& e : chained) {
    if (e.from > x) --e.from;
    if (e.to > x) --e.to;
    addOrFuse(graph, e);
  }
}

bool addOrFuse(Graph2D& graph, const Edge2D& edge) {
  for (auto& e : graph.edges) {
    const bool same = e.from == edge.from && e.to == edge.to;
    const bool reversed = e.from == edge.to && e.to == edge.from;
    if (!same && !reversed) continue;
    Measurement2D incoming{edge.measurement, edge.information};
    if (reversed) incoming = invert(incoming);
    const Measurement2D fused = fuse({e.measurement, e.information}, incoming);
    e.measurement = fused.mean;
    e.information = fused.information;
    e.robust = e.robust || edge.robust;
    return true;
  }
  graph.edges.push_back(edge);
  return false;
}

void initializeFromOdometry(Graph2D& graph) {
  initializeByWalking(
      graph, [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return compose(a, b); },
      [](const Eigen::Vector3d& a) { return inverse(a); });
}

void initializeFromOdometry(Graph3D& graph) {
  initializeByWalking(
      graph, [](const Pose3& a, const Pose3& b) { return a * b; },
      [](const Pose3& a) { return a.inverse(); });
}

}  // namespace tessera::pose_graph
