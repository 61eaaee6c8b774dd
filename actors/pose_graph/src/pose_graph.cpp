#include <tessera/pose_graph/pose_graph.hpp>

#include <tessera/geometry/pose2.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <deque>
#include <map>
#include <numbers>
#include <sstream>
#include <type_traits>

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

namespace {

/// Adj(Z) of SE(2) in the (x, y, θ) chart: Z ⊕ δ ⊕ Z⁻¹ = Adj(Z) δ to first order.
Eigen::Matrix3d adjoint(const Eigen::Vector3d& z) {
  const double c = std::cos(z.z()), s = std::sin(z.z());
  Eigen::Matrix3d a;
  a << c, -s, z.y(),  //
      s, c, -z.x(),   //
      0, 0, 1;
  return a;
}

/// (M + Mᵀ) / 2: exactly symmetric, whatever rounding did to M.
template <class Derived>
typename Derived::PlainObject symmetric(const Eigen::MatrixBase<Derived>& m) {
  return 0.5 * (m + m.transpose());
}

}  // namespace

Eigen::Matrix3d informationFromFrameCovariance(const Eigen::Vector3d& measurement,
                                               const Eigen::Matrix3d& covariance) {
  // A shift δ of Z's (x, y) given in the from frame is the error R(θ_Z)ᵀ δ: Σ_e = A Σ Aᵀ with A
  // a rotation, so Ω_e = A Σ⁻¹ Aᵀ.
  Eigen::Matrix3d a = Eigen::Matrix3d::Identity();
  a.topLeftCorner<2, 2>() = Eigen::Rotation2Dd(-measurement.z()).toRotationMatrix();
  return symmetric(a * symmetric(covariance).inverse() * a.transpose());
}

Measurement2D fuse(const Measurement2D& first, const Measurement2D& second) {
  // One Gauss-Newton step from the first in the edge chart (as in SE(3)):
  // Z = Z1 ⊕ Ω⁻¹ Ω2 (Z1⁻¹ ⊕ Z2).
  const Eigen::Vector3d delta = compose(inverse(first.mean), second.mean);
  Measurement2D out;
  out.information = first.information + second.information;
  out.mean = compose(first.mean, out.information.ldlt().solve(second.information * delta));
  return out;
}

Measurement2D invert(const Measurement2D& m) {
  // The inverse's error is −Adj(Z) e: Ω' = Adj⁻ᵀ Ω Adj⁻¹.
  const Eigen::Matrix3d adj_inv = adjoint(m.mean).inverse();
  Measurement2D out;
  out.mean = inverse(m.mean);
  out.information = symmetric(adj_inv.transpose() * m.information * adj_inv);
  return out;
}

Measurement2D chain(const Measurement2D& a_to_x, const Measurement2D& x_to_b) {
  // (Z1 ⊕ e1) ⊕ (Z2 ⊕ e2) = Z1 Z2 ⊕ (Adj(Z2⁻¹) e1 + e2) to first order.
  const Eigen::Matrix3d j1 = adjoint(inverse(x_to_b.mean));
  const Eigen::Matrix3d cov =
      j1 * a_to_x.information.inverse() * j1.transpose() + x_to_b.information.inverse();
  Measurement2D out;
  out.mean = compose(a_to_x.mean, x_to_b.mean);
  out.information = symmetric(cov.inverse());
  return out;
}

namespace {

template <class G>
using MeasurementOf = std::conditional_t<std::is_same_v<G, Graph2D>, Measurement2D, Measurement3D>;

template <class G>
bool addOrFuseEdge(G& graph, const typename G::EdgeType& edge) {
  using M = MeasurementOf<G>;
  for (auto& e : graph.edges) {
    const bool same = e.from == edge.from && e.to == edge.to;
    const bool reversed = e.from == edge.to && e.to == edge.from;
    if (!same && !reversed) continue;
    M incoming{edge.measurement, edge.information};
    if (reversed) incoming = invert(incoming);
    const M fused = fuse(M{e.measurement, e.information}, incoming);
    e.measurement = fused.mean;
    e.information = fused.information;
    e.robust = e.robust || edge.robust;
    return true;
  }
  graph.edges.push_back(edge);
  return false;
}

template <class G>
void marginalize(G& graph, std::int64_t id) {
  using M = MeasurementOf<G>;
  const int x = graph.index(id);
  if (x == 0)
    throw GraphError("pose graph: node " + std::to_string(id) +
                     " anchors the frame (index 0) and cannot be marginalised");
  // Every edge at x as a measurement x -> neighbour.
  struct Tie {
    int node = 0;
    M from_x;
    bool robust = false;
  };
  std::vector<Tie> ties;
  for (const auto& e : graph.edges) {
    if (e.from == x)
      ties.push_back({e.to, M{e.measurement, e.information}, e.robust});
    else if (e.to == x)
      ties.push_back({e.from, invert(M{e.measurement, e.information}), e.robust});
  }
  std::vector<typename G::EdgeType> chained;
  if (ties.size() > 1) {
    const auto hub = std::max_element(ties.begin(), ties.end(), [](const Tie& a, const Tie& b) {
      return a.from_x.information.determinant() < b.from_x.information.determinant();
    });
    const M hub_to_x = invert(hub->from_x);
    for (const auto& t : ties) {
      if (&t == &*hub || t.node == hub->node) continue;
      const M m = chain(hub_to_x, t.from_x);
      chained.push_back({hub->node, t.node, m.mean, m.information, hub->robust || t.robust});
    }
  }
  graph.removeNode(id);
  for (auto& e : chained) {
    if (e.from > x) --e.from;
    if (e.to > x) --e.to;
    addOrFuseEdge(graph, e);
  }
}

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

/// The edge error's chart of a relative pose d: (translation, quaternion vector part, w >= 0).
Vector6d chartOf(const Pose3& d) {
  Vector6d v;
  v.head<3>() = d.t;
  v.tail<3>() = d.q.w() < 0.0 ? Eigen::Vector3d(-d.q.vec()) : d.q.vec();
  return v;
}

/// z ⊞ δ = z · (δt, the unit quaternion whose vector part is δr).
Pose3 boxplus(const Pose3& z, const Vector6d& d) {
  const Eigen::Vector3d r = d.tail<3>();
  const Eigen::Quaterniond q(std::sqrt(std::max(0.0, 1.0 - r.squaredNorm())), r.x(), r.y(), r.z());
  return z * Pose3{d.head<3>(), q.normalized()};
}

/// Jacobian of `f` (chart -> chart, f(0) = 0) at 0, by central differences.
template <class F>
Matrix6d numericJacobian(const F& f) {
  constexpr double h = 1e-6;
  Matrix6d j;
  for (int i = 0; i < 6; ++i) {
    Vector6d d = Vector6d::Zero();
    d(i) = h;
    j.col(i) = (f(d) - f(-d)) / (2 * h);
  }
  return j;
}

}  // namespace

void marginalizeNode(Graph2D& graph, std::int64_t id) {
  marginalize(graph, id);
}
void marginalizeNode(Graph3D& graph, std::int64_t id) {
  marginalize(graph, id);
}
bool addOrFuse(Graph2D& graph, const Edge2D& edge) {
  return addOrFuseEdge(graph, edge);
}
bool addOrFuse(Graph3D& graph, const Edge3D& edge) {
  return addOrFuseEdge(graph, edge);
}

Measurement3D fuse(const Measurement3D& first, const Measurement3D& second) {
  Measurement3D out;
  out.information = symmetric(first.information + second.information);
  const Vector6d step = out.information.ldlt().solve(second.information *
                                                     chartOf(first.mean.inverse() * second.mean));
  out.mean = boxplus(first.mean, step);
  return out;
}

Measurement3D invert(const Measurement3D& m) {
  const Pose3 z_inv = m.mean.inverse();
  // δ' with (Z ⊞ δ)⁻¹ = Z⁻¹ ⊞ δ'; Ω' = J⁻ᵀ Ω J⁻¹.
  const Matrix6d j = numericJacobian(
      [&](const Vector6d& d) { return chartOf(m.mean * boxplus(m.mean, d).inverse()); });
  const Matrix6d j_inv = j.inverse();
  Measurement3D out;
  out.mean = z_inv;
  out.information = symmetric(j_inv.transpose() * m.information * j_inv);
  return out;
}

Measurement3D chain(const Measurement3D& a_to_x, const Measurement3D& x_to_b) {
  const Pose3 z = a_to_x.mean * x_to_b.mean;
  const Pose3 z_inv = z.inverse();
  const Matrix6d j1 = numericJacobian(
      [&](const Vector6d& d) { return chartOf(z_inv * boxplus(a_to_x.mean, d) * x_to_b.mean); });
  const Matrix6d j2 = numericJacobian(
      [&](const Vector6d& d) { return chartOf(z_inv * a_to_x.mean * boxplus(x_to_b.mean, d)); });
  const Matrix6d cov = j1 * a_to_x.information.inverse() * j1.transpose() +
                       j2 * x_to_b.information.inverse() * j2.transpose();
  Measurement3D out;
  out.mean = z;
  out.information = symmetric(cov.inverse());
  return out;
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
