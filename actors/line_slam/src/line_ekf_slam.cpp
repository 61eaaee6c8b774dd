#include <tessera/line_slam/line_ekf_slam.hpp>

#include <tessera/config/config_check.hpp>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

namespace tessera::line_slam {

using tessera::angleDiff;
using tessera::normalizeAngle;
using tessera::Pose2;
using tessera::line_slam::LineSegment;

namespace {

constexpr double kPi = std::numbers::pi;

Eigen::Vector2d directionOf(double phi) {
  return {-std::sin(phi), std::cos(phi)};
}

/// |Δφ| between two line directions, ignoring which way their normals point.
double undirectedAngle(double a, double b) {
  const double d = std::abs(angleDiff(a, b));
  return std::min(d, kPi - d);
}

bool segmentUsable(const LineSegment& s, double min_length) {
  const auto& c = s.line.covariance;
  return std::isfinite(s.line.r) && std::isfinite(s.line.phi) && s.p0.allFinite() &&
         s.p1.allFinite() && c.allFinite() && c(0, 0) >= 0 && c(1, 1) >= 0 &&
         s.length() >= min_length;
}

}  // namespace

Eigen::Vector2d MapLine::p0() const {
  return r * Eigen::Vector2d(std::cos(phi), std::sin(phi)) + t_min * directionOf(phi);
}

Eigen::Vector2d MapLine::p1() const {
  return r * Eigen::Vector2d(std::cos(phi), std::sin(phi)) + t_max * directionOf(phi);
}

LineEkfSlam::LineEkfSlam(LineEkfSlamOptions o) : options_(o) {
  ConfigCheck()
      .nonNegative("odom_sigma_d", o.odom_sigma_d)
      .nonNegative("odom_sigma_theta_per_m", o.odom_sigma_theta_per_m)
      .nonNegative("odom_sigma_theta", o.odom_sigma_theta)
      .positive("odom_sigma_min", o.odom_sigma_min)
      .nonNegative("speed_sigma", o.speed_sigma)
      .nonNegative("steering_sigma", o.steering_sigma)
      .positive("obs_sigma_r", o.obs_sigma_r)
      .positive("obs_sigma_phi", o.obs_sigma_phi)
      .positive("gate_angle", o.gate_angle)
      .positive("gate_distance", o.gate_distance)
      .nonNegative("gate_overlap", o.gate_overlap)
      .nonNegative("overlap_margin", o.overlap_margin)
      .nonNegative("cost_overlap_weight", o.cost_overlap_weight)
      .require(o.tentative_sightings >= 1, "tentative_sightings", "must be >= 1",
               o.tentative_sightings)
      .nonNegative("min_segment_length", o.min_segment_length)
      .require(o.merge_interval >= 0, "merge_interval", "must be >= 0", o.merge_interval)
      .nonNegative("merge_angle", o.merge_angle)
      .nonNegative("merge_distance", o.merge_distance)
      .nonNegative("merge_gap", o.merge_gap)
      .positive("merge_chi2", o.merge_chi2)
      .throwIfBad();
  reset(Pose2());
}

void LineEkfSlam::reset(const Pose2& pose, const Eigen::Matrix3d& cov) {
  state_ = pose.vector();
  cov_ = cov;
  lines_.clear();
  tentative_.clear();
}

Pose2 LineEkfSlam::pose() const {
  return {state_(0), state_(1), state_(2)};
}

bool LineEkfSlam::predictOdometry(const Pose2& delta) {
  if (!delta.isFinite()) {
    ++stats_.motion_rejected;
    return false;
  }
  const double th = state_(2), c = std::cos(th), s = std::sin(th);
  Eigen::Matrix3d f = Eigen::Matrix3d::Identity();
  f(0, 2) = -s * delta.x - c * delta.y;
  f(1, 2) = c * delta.x - s * delta.y;
  Eigen::Matrix3d g = Eigen::Matrix3d::Identity();
  g.topLeftCorner<2, 2>() << c, -s, s, c;
  const double d = std::hypot(delta.x, delta.y);
  const double sd = std::max(options_.odom_sigma_min, options_.odom_sigma_d * d);
  const double st =
      std::max(options_.odom_sigma_min, options_.odom_sigma_theta_per_m * d +
                                            options_.odom_sigma_theta * std::abs(delta.theta));
  const Eigen::Vector3d q(sd * sd, sd * sd, st * st);

  const Pose2 moved = pose() * delta;
  state_.head<3>() = moved.vector();
  const Eigen::Index n = state_.size();
  cov_.topLeftCorner<3, 3>() =
      f * cov_.topLeftCorner<3, 3>() * f.transpose() + g * q.asDiagonal() * g.transpose();
  if (n > 3) {
    cov_.topRightCorner(3, n - 3) = f * cov_.topRightCorner(3, n - 3);
    cov_.bottomLeftCorner(n - 3, 3) = cov_.topRightCorner(3, n - 3).transpose();
  }
  return true;
}

bool LineEkfSlam::predictCarLike(double v, double gamma, double wheelbase, double dt) {
  if (!std::isfinite(v) || !std::isfinite(gamma) || !std::isfinite(wheelbase) ||
      !std::isfinite(dt) || dt <= 0 || wheelbase <= 0) {
    ++stats_.motion_rejected;
    return false;
  }
  const double th = state_(2), a = th + gamma;
  Eigen::Matrix3d f = Eigen::Matrix3d::Identity();
  f(0, 2) = -dt * v * std::sin(a);
  f(1, 2) = dt * v * std::cos(a);
  Eigen::Matrix<double, 3, 2> g;
  g << dt * std::cos(a), -dt * v * std::sin(a), dt * std::sin(a), dt * v * std::cos(a),
      dt * std::sin(gamma) / wheelbase, dt * v * std::cos(gamma) / wheelbase;
  const Eigen::Vector2d q(options_.speed_sigma * options_.speed_sigma,
                          options_.steering_sigma * options_.steering_sigma);
  state_(0) += dt * v * std::cos(a);
  state_(1) += dt * v * std::sin(a);
  state_(2) = normalizeAngle(th + dt * v * std::sin(gamma) / wheelbase);
  const Eigen::Index n = state_.size();
  cov_.topLeftCorner<3, 3>() =
      f * cov_.topLeftCorner<3, 3>() * f.transpose() + g * q.asDiagonal() * g.transpose() +
      Eigen::Matrix3d::Identity() * options_.odom_sigma_min * options_.odom_sigma_min;
  if (n > 3) {
    cov_.topRightCorner(3, n - 3) = f * cov_.topRightCorner(3, n - 3);
    cov_.bottomLeftCorner(n - 3, 3) = cov_.topRightCorner(3, n - 3).transpose();
  }
  return true;
}

Eigen::Vector2d LineEkfSlam::predict(std::size_t i, Eigen::Matrix<double, 2, 5>* jac) const {
  const Eigen::Index k = 3 + 2 * static_cast<Eigen::Index>(i);
  const double x = state_(0), y = state_(1), th = state_(2);
  const double r = state_(k), phi = state_(k + 1);
  const double c = std::cos(phi), s = std::sin(phi);
  double rp = r - (x * c + y * s);
  double pp = phi - th;
  Eigen::Matrix<double, 2, 5> h;
  h << -c, -s, 0.0, 1.0, x * s - y * c, 0.0, 0.0, -1.0, 0.0, 1.0;
  if (rp < 0) {
    rp = -rp;
    pp += kPi;
    h.row(0) *= -1.0;
  }
  if (jac) *jac = h;
  return {rp, normalizeAngle(pp)};
}

LineEkfSlam::Gates LineEkfSlam::measure(double r, double phi, double t_min, double t_max,
                                        const LineSegment& world) const {
  const Eigen::Vector2d n(std::cos(phi), std::sin(phi)), dir = directionOf(phi);
  Gates g;
  g.angle = undirectedAngle(world.line.phi, phi);
  g.distance = 0.5 * (std::abs(world.p0.dot(n) - r) + std::abs(world.p1.dot(n) - r));
  const double a = std::min(world.p0.dot(dir), world.p1.dot(dir));
  const double b = std::max(world.p0.dot(dir), world.p1.dot(dir));
  const double lo = std::max(a, t_min - options_.overlap_margin);
  const double hi = std::min(b, t_max + options_.overlap_margin);
  g.overlap = std::max(0.0, hi - lo) / std::max(b - a, 1e-9);
  return g;
}

bool LineEkfSlam::passes(const Gates& g) const {
  return g.angle <= options_.gate_angle && g.distance <= options_.gate_distance &&
         g.overlap >= options_.gate_overlap;
}

Eigen::Matrix2d LineEkfSlam::observationNoise(const LineSegment& s) const {
  Eigen::Matrix2d r = s.line.covariance;
  r(0, 0) += options_.obs_sigma_r * options_.obs_sigma_r;
  r(1, 1) += options_.obs_sigma_phi * options_.obs_sigma_phi;
  return r;
}

int LineEkfSlam::associate(const LineSegment& robot_segment, bool* ambiguous) const {
  const LineSegment world = tessera::line_slam::transformSegment(robot_segment, pose());
  const Eigen::Matrix2d r = observationNoise(robot_segment);
  int best = -1, candidates = 0;
  double best_cost = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < lines_.size(); ++i) {
    const Eigen::Index k = 3 + 2 * static_cast<Eigen::Index>(i);
    const Gates g = measure(state_(k), state_(k + 1), lines_[i].t_min, lines_[i].t_max, world);
    if (!passes(g)) continue;
    ++candidates;
    if (options_.association == Association::kThreshold) {
      if (best < 0) best = static_cast<int>(i);  // the old method: first within the gates
      continue;
    }
    // Weights are inverse variances of the innovation: the angle and distance terms are
    // normalised by what the filter expects them to scatter by.
    Eigen::Matrix<double, 2, 5> h;
    predict(i, &h);
    const std::array<Eigen::Index, 5> idx{0, 1, 2, k, k + 1};
    Eigen::Matrix<double, 5, 5> p;
    for (int a = 0; a < 5; ++a)
      for (int b = 0; b < 5; ++b) p(a, b) = cov_(idx[a], idx[b]);
    const Eigen::Matrix2d s = h * p * h.transpose() + r;
    const double cost = g.angle * g.angle / s(1, 1) + g.distance * g.distance / s(0, 0) +
                        options_.cost_overlap_weight * (1 - std::min(g.overlap, 1.0)) *
                            (1 - std::min(g.overlap, 1.0));
    if (cost < best_cost) {
      best_cost = cost;
      best = static_cast<int>(i);
    }
  }
  if (ambiguous) *ambiguous = candidates > 1;
  return best;
}

bool LineEkfSlam::ekfUpdate(std::size_t i, const LineSegment& seg) {
  Eigen::Matrix<double, 2, 5> h;
  const Eigen::Vector2d zhat = predict(i, &h);
  Eigen::Vector2d z(seg.line.r, seg.line.phi);
  // A line passing close to the robot may be observed with its normal the other way round.
  if (std::abs(angleDiff(z(1), zhat(1))) > kPi / 2) {
    z(0) = -z(0);
    z(1) = normalizeAngle(z(1) + kPi);
  }
  const Eigen::Vector2d nu(z(0) - zhat(0), angleDiff(z(1), zhat(1)));
  const Eigen::Index k = 3 + 2 * static_cast<Eigen::Index>(i);
  const std::array<Eigen::Index, 5> idx{0, 1, 2, k, k + 1};
  const Eigen::Index n = state_.size();
  Eigen::MatrixXd pht = Eigen::MatrixXd::Zero(n, 2);  // P Hᵀ, using H's 5 non-zero columns
  for (int a = 0; a < 5; ++a) pht += cov_.col(idx[a]) * h.col(a).transpose();
  Eigen::Matrix2d s = observationNoise(seg);
  for (int a = 0; a < 5; ++a) s += h.col(a) * pht.row(idx[a]);
  const Eigen::LDLT<Eigen::Matrix2d> ldlt(s);
  if (ldlt.info() != Eigen::Success || !(s.determinant() > 0)) {
    ++stats_.update_failures;
    return false;
  }
  const Eigen::MatrixXd kgain = ldlt.solve(pht.transpose()).transpose();  // n x 2
  state_ += kgain * nu;
  cov_ -= kgain * pht.transpose();
  cov_ = 0.5 * (cov_ + cov_.transpose());
  state_(2) = normalizeAngle(state_(2));
  for (std::size_t j = 0; j < lines_.size(); ++j) normalizeLineState(j);
  return true;
}

void LineEkfSlam::normalizeLineState(std::size_t i) {
  const Eigen::Index k = 3 + 2 * static_cast<Eigen::Index>(i);
  if (state_(k) < 0) {
    state_(k) = -state_(k);
    state_(k + 1) += kPi;
    cov_.row(k) *= -1.0;
    cov_.col(k) *= -1.0;
    // The direction vector flips with the normal: the extent is mirrored.
    const double lo = -lines_[i].t_max, hi = -lines_[i].t_min;
    lines_[i].t_min = lo;
    lines_[i].t_max = hi;
  }
  state_(k + 1) = normalizeAngle(state_(k + 1));
}

void LineEkfSlam::extend(std::size_t i, const LineSegment& world) {
  const Eigen::Index k = 3 + 2 * static_cast<Eigen::Index>(i);
  const Eigen::Vector2d dir = directionOf(state_(k + 1));
  for (const auto& p : {world.p0, world.p1}) {
    lines_[i].t_min = std::min(lines_[i].t_min, p.dot(dir));
    lines_[i].t_max = std::max(lines_[i].t_max, p.dot(dir));
  }
  ++lines_[i].observations;
}

void LineEkfSlam::addLine(const LineSegment& seg) {
  const double x = state_(0), y = state_(1), th = state_(2);
  const double phi = seg.line.phi + th;
  const double r = seg.line.r + x * std::cos(phi) + y * std::sin(phi);
  const double dr_dphi = -x * std::sin(phi) + y * std::cos(phi);
  Eigen::Matrix<double, 2, 3> gx;
  gx << std::cos(phi), std::sin(phi), dr_dphi, 0.0, 0.0, 1.0;
  Eigen::Matrix2d gz;
  gz << 1.0, dr_dphi, 0.0, 1.0;
  double r_new = r, phi_new = phi;
  if (r < 0) {
    gx.row(0) *= -1.0;
    gz.row(0) *= -1.0;
  }
  tessera::line_slam::normalizeLine(r_new, phi_new);

  const Eigen::Index n = state_.size();
  state_.conservativeResize(n + 2);
  state_(n) = r_new;
  state_(n + 1) = phi_new;
  // P_new = G_x P G_xᵀ + G_z R G_zᵀ; the cross terms with everything else are G_x P_{pose,·}.
  const Eigen::MatrixXd cross = gx * cov_.topRows(3);  // 2 x n
  const Eigen::Matrix2d pnn = gx * cov_.topLeftCorner<3, 3>() * gx.transpose() +
                              gz * observationNoise(seg) * gz.transpose();
  cov_.conservativeResize(n + 2, n + 2);
  cov_.block(n, 0, 2, n) = cross;
  cov_.block(0, n, n, 2) = cross.transpose();
  cov_.block<2, 2>(n, n) = pnn;

  LineMeta meta{next_id_++, std::numeric_limits<double>::infinity(),
                -std::numeric_limits<double>::infinity(), 0};
  lines_.push_back(meta);
  extend(lines_.size() - 1, tessera::line_slam::transformSegment(seg, pose()));
  ++stats_.lines_added;
}

void LineEkfSlam::removeLine(std::size_t i) {
  const Eigen::Index k = 3 + 2 * static_cast<Eigen::Index>(i);
  const Eigen::Index n = state_.size(), tail = n - k - 2;
  if (tail > 0) {
    state_.segment(k, tail) = state_.tail(tail).eval();
    cov_.block(k, 0, tail, n) = cov_.bottomRows(tail).eval();
    cov_.block(0, k, n, tail) = cov_.rightCols(tail).eval();
  }
  state_.conservativeResize(n - 2);
  cov_.conservativeResize(n - 2, n - 2);
  lines_.erase(lines_.begin() + static_cast<std::ptrdiff_t>(i));
}

void LineEkfSlam::mergeDuplicates() {
  bool merged = true;
  while (merged) {
    merged = false;
    for (std::size_t i = 0; i < lines_.size() && !merged; ++i) {
      for (std::size_t j = i + 1; j < lines_.size() && !merged; ++j) {
        const Eigen::Index ki = 3 + 2 * static_cast<Eigen::Index>(i);
        const Eigen::Index kj = 3 + 2 * static_cast<Eigen::Index>(j);
        const double dphi = angleDiff(state_(ki + 1), state_(kj + 1));
        if (std::abs(dphi) > options_.merge_angle ||
            std::abs(state_(ki) - state_(kj)) > options_.merge_distance)
          continue;
        // j's extent in i's direction (the directions agree within merge_angle).
        const Eigen::Vector2d di = directionOf(state_(ki + 1)), dj = directionOf(state_(kj + 1));
        const Eigen::Vector2d foot_j =
            state_(kj) * Eigen::Vector2d(std::cos(state_(kj + 1)), std::sin(state_(kj + 1)));
        const double a = (foot_j + lines_[j].t_min * dj).dot(di);
        const double b = (foot_j + lines_[j].t_max * dj).dot(di);
        const double gap =
            std::max(std::min(a, b) - lines_[i].t_max, lines_[i].t_min - std::max(a, b));
        if (gap > options_.merge_gap) continue;
        // Mahalanobis test of l_i − l_j = 0.
        const Eigen::Vector2d delta(state_(ki) - state_(kj), dphi);
        const Eigen::Matrix2d s = cov_.block<2, 2>(ki, ki) + cov_.block<2, 2>(kj, kj) -
                                  cov_.block<2, 2>(ki, kj) - cov_.block<2, 2>(kj, ki) +
                                  Eigen::Matrix2d::Identity() * 1e-10;
        const Eigen::LDLT<Eigen::Matrix2d> ldlt(s);
        if (ldlt.info() != Eigen::Success) continue;
        if (delta.dot(ldlt.solve(delta)) > options_.merge_chi2) continue;
        // Fuse: EKF update with the perfect pseudo-measurement l_i − l_j = 0.
        const Eigen::MatrixXd pht = cov_.middleCols(ki, 2) - cov_.middleCols(kj, 2);  // n x 2
        const Eigen::MatrixXd kgain = ldlt.solve(pht.transpose()).transpose();
        state_ -= kgain * delta;
        cov_ -= kgain * pht.transpose();
        cov_ = 0.5 * (cov_ + cov_.transpose());
        state_(2) = normalizeAngle(state_(2));
        const std::int64_t obs = lines_[j].observations;
        const Eigen::Vector2d pj0 = foot_j + lines_[j].t_min * dj;
        const Eigen::Vector2d pj1 = foot_j + lines_[j].t_max * dj;
        removeLine(j);
        for (std::size_t m = 0; m < lines_.size(); ++m) normalizeLineState(m);
        LineSegment span;
        span.p0 = pj0;
        span.p1 = pj1;
        extend(i, span);
        lines_[i].observations += obs - 1;
        ++stats_.lines_merged;
        merged = true;
      }
    }
  }
}

int LineEkfSlam::update(const std::vector<LineSegment>& segments) {
  stats_.segments += segments.size();
  ++stats_.updates;
  int matched = 0;
  std::vector<LineSegment> unmatched;  // robot frame
  for (const auto& seg : segments) {
    if (!segmentUsable(seg, options_.min_segment_length)) {
      ++stats_.segments_rejected;
      continue;
    }
    bool ambiguous = false;
    const int k = associate(seg, &ambiguous);
    if (ambiguous) ++stats_.ambiguous;
    if (k < 0) {
      unmatched.push_back(seg);
      continue;
    }
    if (!ekfUpdate(static_cast<std::size_t>(k), seg)) continue;
    extend(static_cast<std::size_t>(k), tessera::line_slam::transformSegment(seg, pose()));
    ++stats_.matched;
    ++matched;
  }

  // New lines: tentative until seen in `tentative_sightings` consecutive updates.
  const std::uint64_t step = stats_.updates;
  for (const auto& seg : unmatched) {
    if (options_.tentative_sightings <= 1) {
      addLine(seg);
      continue;
    }
    const LineSegment world = tessera::line_slam::transformSegment(seg, pose());
    bool found = false;
    for (std::size_t t = 0; t < tentative_.size() && !found; ++t) {
      Tentative& cand = tentative_[t];
      if (cand.last_update + 1 != step) continue;  // already seen in this update, or stale
      const Eigen::Vector2d dir = directionOf(cand.world.line.phi);
      const double a = cand.world.p0.dot(dir), b = cand.world.p1.dot(dir);
      if (!passes(measure(cand.world.line.r, cand.world.line.phi, std::min(a, b), std::max(a, b),
                          world)))
        continue;
      found = true;
      cand.world = world;
      cand.last_update = step;
      if (++cand.sightings >= options_.tentative_sightings) {
        addLine(seg);
        ++stats_.tentative_promoted;
        tentative_.erase(tentative_.begin() + static_cast<std::ptrdiff_t>(t));
      }
    }
    if (!found) {
      tentative_.push_back({world, 1, step});
      ++stats_.tentative_created;
    }
  }
  const auto stale = [step](const Tentative& t) { return t.last_update != step; };
  stats_.tentative_dropped +=
      static_cast<std::uint64_t>(std::count_if(tentative_.begin(), tentative_.end(), stale));
  std::erase_if(tentative_, stale);

  if (options_.merge_interval > 0 &&
      step % static_cast<std::uint64_t>(options_.merge_interval) == 0)
    mergeDuplicates();
  return matched;
}

std::vector<MapLine> LineEkfSlam::lines() const {
  std::vector<MapLine> out;
  out.reserve(lines_.size());
  for (std::size_t i = 0; i < lines_.size(); ++i) {
    const Eigen::Index k = 3 + 2 * static_cast<Eigen::Index>(i);
    MapLine l;
    l.id = lines_[i].id;
    l.r = state_(k);
    l.phi = state_(k + 1);
    l.covariance = cov_.block<2, 2>(k, k);
    l.t_min = lines_[i].t_min;
    l.t_max = lines_[i].t_max;
    l.observations = lines_[i].observations;
    out.push_back(l);
  }
  return out;
}

}  // namespace tessera::line_slam
