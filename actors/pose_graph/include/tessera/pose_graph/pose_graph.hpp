// Pose graphs in SE(2) and SE(3): nodes (poses in one global frame), edges (relative-pose
// measurements with information matrices), the one error/χ² evaluator every solver shares, and
// constraint fusion.
//
// Conventions are g2o's, so figures compare with g2o's own:
//  * An edge a -> b measures Z = the pose of b in the frame of a.
//  * Its error is e = t2v(Z⁻¹ (X_a⁻¹ X_b)). SE(2): (dx, dy, dθ) with dθ wrapped to (−π, π].
//    SE(3): (translation, imaginary part of the unit quaternion with w ≥ 0), the information
//    matrix ordered (translation, rotation) like g2o's EDGE_SE3:QUAT.
//  * χ² = Σ eᵀ Ω e, without the ½ that Ceres reports as its cost.
// Units: metres and radians. Nodes are stored densely (index 0..n−1); `ids` keeps the ids of
// the file or the caller. Plain data: the graph owns its nodes and edges; solvers change `poses`
// in place and never the edges.
#pragma once

#include <tessera/geometry/pose3.hpp>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

namespace tessera::pose_graph {

/// Thrown for graphs a solver cannot work on (unknown node, non-finite values, empty graph).
struct GraphError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

template <class Pose, int Dim>
struct Edge {
  using Information = Eigen::Matrix<double, Dim, Dim>;
  int from = 0;  ///< node index
  int to = 0;    ///< node index
  Pose measurement{};
  Information information = Information::Identity();
  /// Loop closures get the robust loss in solvers that offer one; odometry and submap hand-over
  /// edges are trusted as they are.
  bool robust = false;
};

template <class Pose, int Dim>
struct Graph {
  using PoseType = Pose;
  using EdgeType = Edge<Pose, Dim>;
  static constexpr int kDim = Dim;

  std::vector<std::int64_t> ids;  ///< caller's id of each node
  std::vector<Pose> poses;        ///< estimate of each node in the global frame
  std::vector<bool> fixed;        ///< nodes the solvers keep where they are
  std::vector<EdgeType> edges;

  int size() const { return static_cast<int>(poses.size()); }
  /// Appends a node and returns its index. Throws GraphError if the id is already used.
  int addNode(std::int64_t id, const Pose& pose, bool is_fixed = false);
  /// Index of the node with this id; throws GraphError naming the id when there is none.
  int index(std::int64_t id) const;
  bool contains(std::int64_t id) const { return index_.count(id) != 0; }
  /// Removes node `id` and every edge touching it; the nodes after it move down one index (edges
  /// are renumbered). Throws GraphError when there is no such node.
  void removeNode(std::int64_t id);

 private:
  std::unordered_map<std::int64_t, int> index_;
};

/// SE(2) nodes are (x, y, θ) vectors.
using Graph2D = Graph<Eigen::Vector3d, 3>;
using Graph3D = Graph<Pose3, 6>;
using Edge2D = Graph2D::EdgeType;
using Edge3D = Graph3D::EdgeType;

// --- SE(2) helpers over (x, y, θ) vectors ---------------------------------------------------
Eigen::Vector3d compose(const Eigen::Vector3d& a, const Eigen::Vector3d& b);
Eigen::Vector3d inverse(const Eigen::Vector3d& a);
/// a⁻¹ b: the pose of b in the frame of a, θ wrapped.
Eigen::Vector3d between(const Eigen::Vector3d& a, const Eigen::Vector3d& b);

// --- The evaluator ----------------------------------------------------------------------------
Eigen::Vector3d edgeError(const Graph2D& graph, const Edge2D& edge);
Eigen::Matrix<double, 6, 1> edgeError(const Graph3D& graph, const Edge3D& edge);
Eigen::Vector3d edgeError(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                          const Eigen::Vector3d& measurement);
Eigen::Matrix<double, 6, 1> edgeError(const Pose3& a, const Pose3& b, const Pose3& measurement);
double chi2(const Graph2D& graph);
double chi2(const Graph3D& graph);

/// Checks indices, finiteness and symmetric positive-semidefinite information; throws
/// GraphError naming the first bad edge or node.
void validate(const Graph2D& graph);
void validate(const Graph3D& graph);

// --- Constraint fusion (docs/algorithms.md#constraint-fusion)
// ---------------------------------------------------------------
// Uncertainty lives in the chart of the edge error, as in g2o's objective: Z ⊞ δ = Z ⊕ δ, so
// an information matrix weighs (x, y) along the axes of the end frame X_a ⊕ Z, not of a's frame.
struct Measurement2D {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Matrix3d information = Eigen::Matrix3d::Identity();
};
/// The information of an edge whose covariance is given over Z's (x [m], y [m], θ [rad]) in the
/// from node's frame, as the scan matchers and cameras report it: the (x, y) block turned by
/// −θ_Z into the edge's chart. The same matrix when θ_Z = 0 or the (x, y) block is isotropic.
Eigen::Matrix3d informationFromFrameCovariance(const Eigen::Vector3d& measurement,
                                               const Eigen::Matrix3d& covariance);
/// Information-weighted mean of two measurements of the same relative pose, one Gauss-Newton
/// step from the first: Ω = Ω1 + Ω2, Z = Z1 ⊕ Ω⁻¹ Ω2 (Z1⁻¹ ⊕ Z2).
Measurement2D fuse(const Measurement2D& first, const Measurement2D& second);
/// The same relative pose seen from the other end: Z⁻¹, with the information carried through
/// the adjoint (the inverse's error is −Adj(Z) e).
Measurement2D invert(const Measurement2D& m);

/// Chains two measurements: a -> x then x -> b gives a -> b, Z = Z1 ⊕ Z2, the covariances carried
/// to the end frame (first order; the two taken as independent).
Measurement2D chain(const Measurement2D& a_to_x, const Measurement2D& x_to_b);

/// Removes node `id` and keeps what its edges said about its neighbours
/// (docs/algorithms.md#lifelong-mapping): one neighbour, the one tied to it by the most informative
/// edge (largest det Ω), becomes the hub, and each other neighbour n gets the chained edge hub ->
/// id -> n, fused into an edge hub–n if there is one. A star rather than the dense clique exact
/// marginalisation would give: the graph stays as sparse as it was (k neighbours give k − 1 edges),
/// at the price of dropping the correlations between the new edges. A chained edge is robust if
/// either input was. Throws GraphError for an unknown id or for index 0, which anchors the frame.
void marginalizeNode(Graph2D& graph, std::int64_t id);

/// Adds the edge, or fuses it into an existing edge between the same two nodes (in either
/// direction) so revisits do not grow the graph. Returns true when it fused. The fused edge is
/// robust if either input was.
bool addOrFuse(Graph2D& graph, const Edge2D& edge);

// --- The same in SE(3) ------------------------------------------------------------------------
// Uncertainty lives in the chart of the edge error: Z ⊞ δ = Z · (δt, unit quaternion with vector
// part δr), so an information matrix means what it means on an edge (rotation as the imaginary
// part of the quaternion, about half the angle). The Jacobians of inversion and composition are
// taken numerically in that chart (central differences); first order, as in SE(2).
struct Measurement3D {
  Pose3 mean;
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Identity();
};
/// Ω = Ω1 + Ω2, Z = Z1 ⊞ Ω⁻¹ Ω2 (Z2 ⊟ Z1): one Gauss-Newton step from the first.
Measurement3D fuse(const Measurement3D& first, const Measurement3D& second);
Measurement3D invert(const Measurement3D& m);
Measurement3D chain(const Measurement3D& a_to_x, const Measurement3D& x_to_b);
void marginalizeNode(Graph3D& graph, std::int64_t id);
bool addOrFuse(Graph3D& graph, const Edge3D& edge);

/// Places every node by walking edges outward from node 0 (odometry edges i -> i+1 first, then
/// a breadth-first walk over all edges), ignoring the current estimates: the "poor initial
/// estimate" start of the SGD paper. Throws GraphError if some node is not connected.
void initializeFromOdometry(Graph2D& graph);
void initializeFromOdometry(Graph3D& graph);

}  // namespace tessera::pose_graph
