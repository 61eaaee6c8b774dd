// Olson–Leonard–Teller SGD (docs/algorithms.md#sgd-on-the-incremental-parameterisation) over nodes
// in index order.
//
// Poses are kept in the global frame; the "incremental parameterisation" shows up as the rule
// that a step given to node i moves every later node too. A constraint a < b spreads its step
// over (a, b] and shifts everything after b by the full step. That suffix shift is kept in a
// Fenwick tree (one O(log n) add instead of touching every later node), so a constraint costs
// O(b − a + log n).
#include "solvers.hpp"

#include <tessera/geometry/pose2.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <random>

namespace tessera::pose_graph::detail {
namespace {

using tessera::normalizeAngle;

/// Adds a vector to every index >= i; reads the sum that reached one index.
template <int D>
class SuffixAdd {
 public:
  using Vec = Eigen::Matrix<double, D, 1>;
  explicit SuffixAdd(int n) : tree_(n + 1, Vec::Zero()) {}
  void add(int i, const Vec& v) {
    for (int k = i + 1; k < static_cast<int>(tree_.size()); k += k & -k) tree_[k] += v;
  }
  Vec at(int i) const {
    Vec sum = Vec::Zero();
    for (int k = i + 1; k > 0; k -= k & -k) sum += tree_[k];
    return sum;
  }
  void clear() { std::fill(tree_.begin(), tree_.end(), Vec::Zero()); }

 private:
  std::vector<Vec> tree_;
};

/// Per-pass preconditioner M_i (sum of diag(W) of the constraints spanning node i), with O(1)
/// range minimum (sparse table) and range sums of 1/M.
template <int D>
class Preconditioner {
 public:
  using Vec = Eigen::Matrix<double, D, 1>;
  void build(int n, const std::vector<std::pair<int, int>>& spans, const std::vector<Vec>& diag) {
    std::vector<Vec> delta(n + 1, Vec::Zero());
    std::vector<int> count_delta(n + 1, 0);
    for (std::size_t c = 0; c < spans.size(); ++c) {
      delta[spans[c].first + 1] += diag[c];
      delta[spans[c].second + 1] -= diag[c];
      ++count_delta[spans[c].first + 1];
      --count_delta[spans[c].second + 1];
    }
    m_.assign(n, Vec::Zero());
    inverse_prefix_.assign(n + 1, Vec::Zero());
    Vec run = Vec::Zero();
    int spanning = 0;
    for (int i = 0; i < n; ++i) {
      run += delta[i];
      spanning += count_delta[i];
      // A node no constraint spans (node 0 at least) never takes a step. It must not add to the
      // prefix sums either: one huge 1/M there would swamp every later difference.
      m_[i] = spanning > 0 ? Vec(run.cwiseMax(Vec::Constant(1e-12))) : Vec::Constant(1e300);
      inverse_prefix_[i + 1] =
          inverse_prefix_[i] + (spanning > 0 ? Vec(m_[i].cwiseInverse()) : Vec(Vec::Zero()));
    }
    levels_.assign(1, m_);
    for (int width = 2; width <= n; width *= 2) {
      const auto& prev = levels_.back();
      std::vector<Vec> next(n - width + 1);
      for (int i = 0; i + width <= n; ++i) next[i] = prev[i].cwiseMin(prev[i + width / 2]);
      levels_.push_back(std::move(next));
    }
  }
  const Vec& at(int i) const { return m_[i]; }
  /// Minimum over nodes first..last (inclusive).
  Vec min(int first, int last) const {
    const int len = last - first + 1;
    const int level = std::bit_width(static_cast<unsigned>(len)) - 1;
    return levels_[level][first].cwiseMin(levels_[level][last - (1 << level) + 1]);
  }
  /// Σ 1/M over nodes first..last (inclusive).
  Vec inverseSum(int first, int last) const {
    return inverse_prefix_[last + 1] - inverse_prefix_[first];
  }

 private:
  std::vector<Vec> m_;
  std::vector<Vec> inverse_prefix_;
  std::vector<std::vector<Vec>> levels_;
};

/// β per dimension (docs/algorithms.md#sgd-on-the-incremental-parameterisation): the preconditioned
/// step, clipped to the residual.
template <int D>
Eigen::Matrix<double, D, 1> stepSize(const Eigen::Matrix<double, D, 1>& d,
                                     const Eigen::Matrix<double, D, 1>& residual, int span,
                                     const Eigen::Matrix<double, D, 1>& gamma, int pass) {
  Eigen::Matrix<double, D, 1> beta;
  for (int k = 0; k < D; ++k) {
    const double alpha = 1.0 / (gamma[k] * pass);
    const double limit = std::abs(residual[k]);
    beta[k] = std::clamp(span * d[k] * alpha, -limit, limit);
  }
  return beta;
}

std::vector<std::size_t> shuffledOrder(std::size_t count, std::mt19937_64& rng) {
  std::vector<std::size_t> order(count);
  for (std::size_t i = 0; i < count; ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);
  return order;
}

Eigen::Matrix3d planarRotation(double theta) {
  const double c = std::cos(theta), s = std::sin(theta);
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  r(0, 0) = c;
  r(0, 1) = -s;
  r(1, 0) = s;
  r(1, 1) = c;
  return r;
}

bool stop(const SgdOptions& options, double before, double after) {
  return options.relative_decrease > 0.0 && before > 0.0 &&
         (before - after) / before < options.relative_decrease && after <= before;
}

}  // namespace

namespace {

/// A constraint oriented a < b (an edge b -> a is used through its inverse), over the three
/// coordinates SGD moves; omega is the information of those coordinates in a's frame.
template <class Measurement>
struct Constraint {
  int a, b;
  Measurement z;
  Eigen::Matrix3d omega;
};

/// SE(2): SGD moves (x, y, θ).
struct PlanarModel {
  using Pose = Eigen::Vector3d;
  static Constraint<Pose> orient(const Edge2D& e) {
    if (e.from < e.to) return {e.from, e.to, e.measurement, e.information};
    const Measurement2D inv = invert({e.measurement, e.information});
    return {e.to, e.from, inv.mean, inv.information};
  }
  static Eigen::Vector3d& coords(Pose& p) { return p; }
  static Pose shifted(const Pose& p, const Eigen::Vector3d& s) { return p + s; }
  static Eigen::Matrix3d rotation(const Pose& p) { return planarRotation(p.z()); }
  /// The frame Ω is expressed in: g2o's error Z⁻¹ (X_a⁻¹ X_b) lives in the frame of X_a ⊕ Z.
  static Eigen::Matrix3d errorFrame(const Pose& pa, const Pose& z) {
    return planarRotation(pa.z() + z.z());
  }
  static Eigen::Vector3d residual(const Pose& pa, const Pose& pb, const Pose& z) {
    Eigen::Vector3d target = pa;
    target.head<2>() += rotation(pa).topLeftCorner<2, 2>() * z.head<2>();
    Eigen::Vector3d r = target - pb;
    r.z() = normalizeAngle(pa.z() + z.z() - pb.z());
    return r;
  }
  static void finish(Pose& p) { p.z() = normalizeAngle(p.z()); }
};

/// SE(3): SGD moves translations only. Spreading rotation residuals the same way (rotation
/// vectors in the global frame) sent sphere2500 into a worse basin (Ceres then ended at χ² 7074
/// instead of 727), so rotations are left to Ceres.
struct SpatialModel {
  using Pose = Pose3;
  static Constraint<Pose> orient(const Edge3D& e) {
    const Eigen::Matrix3d omega = e.information.topLeftCorner<3, 3>();
    if (e.from < e.to) return {e.from, e.to, e.measurement, omega};
    // Ω weighs along R_a R_Z (≈ b's axes); the inverse's error frame is R_b R_Zᵀ, in which the
    // same axes are R_Z Ω R_Zᵀ.
    const Eigen::Matrix3d r = e.measurement.q.toRotationMatrix();
    return {e.to, e.from, e.measurement.inverse(), r * omega * r.transpose()};
  }
  static Eigen::Vector3d& coords(Pose& p) { return p.t; }
  static Pose shifted(const Pose& p, const Eigen::Vector3d& s) { return {p.t + s, p.q}; }
  static Eigen::Matrix3d rotation(const Pose& p) { return p.q.toRotationMatrix(); }
  static Eigen::Matrix3d errorFrame(const Pose& pa, const Pose& z) {
    return (pa.q * z.q).toRotationMatrix();
  }
  static Eigen::Vector3d residual(const Pose& pa, const Pose& pb, const Pose& z) {
    return pa.t + rotation(pa) * z.t - pb.t;
  }
  static void finish(Pose&) {}
};

template <class Model, class G>
StageResult runPasses(G& graph, const SgdOptions& options) {
  using Pose = typename Model::Pose;
  const int n = graph.size();
  std::vector<Constraint<Pose>> constraints;
  std::vector<std::pair<int, int>> spans;
  for (const auto& e : graph.edges) {
    constraints.push_back(Model::orient(e));
    spans.emplace_back(constraints.back().a, constraints.back().b);
  }
  std::mt19937_64 rng(options.seed);
  SuffixAdd<3> shift(n);
  Preconditioner<3> precond;
  std::vector<Eigen::Vector3d> diag;
  auto pose = [&](int i) { return Model::shifted(graph.poses[i], shift.at(i)); };

  StageResult result;
  double previous = chi2(graph);
  for (int pass = 1; pass <= options.iterations; ++pass) {
    diag.clear();
    for (const auto& c : constraints) {
      const Eigen::Matrix3d r = Model::errorFrame(graph.poses[c.a], c.z);
      diag.push_back((r * c.omega * r.transpose()).diagonal());
    }
    precond.build(n, spans, diag);
    for (std::size_t idx : shuffledOrder(constraints.size(), rng)) {
      const auto& c = constraints[idx];
      const Pose pa = pose(c.a);
      const Eigen::Matrix3d r = Model::errorFrame(pa, c.z);
      const Eigen::Vector3d residual = Model::residual(pa, pose(c.b), c.z);
      const Eigen::Vector3d d = 2.0 * (r * c.omega * r.transpose()) * residual;
      const Eigen::Vector3d beta =
          stepSize<3>(d, residual, c.b - c.a, precond.min(c.a + 1, c.b), pass);
      const Eigen::Vector3d total_weight = precond.inverseSum(c.a + 1, c.b);
      Eigen::Vector3d step = Eigen::Vector3d::Zero();
      for (int i = c.a + 1; i <= c.b; ++i) {
        step += beta.cwiseQuotient(precond.at(i).cwiseProduct(total_weight));
        Model::coords(graph.poses[i]) += step;
      }
      if (c.b + 1 < n) shift.add(c.b + 1, beta);
    }
    for (int i = 0; i < n; ++i) {
      Model::coords(graph.poses[i]) += shift.at(i);
      Model::finish(graph.poses[i]);
    }
    shift.clear();
    result.iterations = pass;
    const double now = chi2(graph);
    if (stop(options, previous, now)) {
      result.converged = true;
      break;
    }
    previous = now;
  }
  result.message = "SGD: " + std::to_string(result.iterations) + " passes";
  return result;
}

}  // namespace

StageResult runSgd(Graph2D& graph, const SgdOptions& options) {
  return runPasses<PlanarModel>(graph, options);
}

StageResult runSgd(Graph3D& graph, const SgdOptions& options) {
  return runPasses<SpatialModel>(graph, options);
}

}  // namespace tessera::pose_graph::detail
