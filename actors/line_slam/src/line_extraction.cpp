#include <tessera/line_slam/line_extraction.hpp>

#include <tessera/config/config_check.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

namespace tessera::line_slam {

Eigen::Vector2d LineFit::normal() const {
  return {std::cos(phi), std::sin(phi)};
}

Eigen::Vector2d LineFit::direction() const {
  return {-std::sin(phi), std::cos(phi)};
}

double LineFit::distance(const Eigen::Vector2d& p) const {
  return p.dot(normal()) - r;
}

void normalizeLine(double& r, double& phi) {
  if (r < 0) {
    r = -r;
    phi += std::numbers::pi;
  }
  phi = normalizeAngle(phi);
}

LineFit fitLineWtls(std::span<const Eigen::Vector2d> points, std::span<const double> weights,
                    double sigma, std::span<const double> point_sigma) {
  LineFit f;
  const std::size_t n = points.size();
  if (n < 2 || (!weights.empty() && weights.size() != n) ||
      (!point_sigma.empty() && point_sigma.size() != n))
    return f;
  const auto w = [&](std::size_t j) { return weights.empty() ? 1.0 : weights[j]; };
  const auto s = [&](std::size_t j) { return point_sigma.empty() ? sigma : point_sigma[j]; };
  double sw = 0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (std::size_t j = 0; j < n; ++j) {
    sw += w(j);
    mean += w(j) * points[j];
  }
  if (!(sw > 0) || !mean.allFinite()) return f;
  mean /= sw;
  double sxx = 0, syy = 0, sxy = 0;
  for (std::size_t j = 0; j < n; ++j) {
    const Eigen::Vector2d d = points[j] - mean;
    sxx += w(j) * d.x() * d.x();
    syy += w(j) * d.y() * d.y();
    sxy += w(j) * d.x() * d.y();
  }
  if (sxx + syy <= 0) return f;  // all weight on one point: no direction
  f.phi = 0.5 * std::atan2(-2.0 * sxy, syy - sxx);
  f.r = mean.x() * std::cos(f.phi) + mean.y() * std::sin(f.phi);
  normalizeLine(f.r, f.phi);

  // First-order propagation of isotropic point noise through the weighted fit: the centroid's
  // normal offset c_n and the rotation φ are linear in the points' normal displacements e_j:
  //   c_n = Σ w e / W,  δφ = −Σ w (t − t̄) e / S_tt,   r = c·n(φ) ⇒ δr = c_n + t̄ δφ.
  const Eigen::Vector2d dir = f.direction();
  const double tbar = mean.dot(dir);
  double stt = 0, vcc = 0, vpp = 0, vcp = 0, sq = 0, chi2 = 0;
  int used = 0;
  for (std::size_t j = 0; j < n; ++j) {
    if (!(w(j) > 0)) continue;
    const double t = points[j].dot(dir) - tbar;
    stt += w(j) * t * t;
  }
  for (std::size_t j = 0; j < n; ++j) {
    if (!(w(j) > 0)) continue;
    const double t = points[j].dot(dir) - tbar;
    const double var = std::max(s(j) * s(j), 1e-12);
    const double ww = w(j) * w(j) * var;
    vcc += ww;
    vpp += ww * t * t;
    vcp -= ww * t;
    const double e = f.distance(points[j]);
    sq += w(j) * e * e;
    chi2 += e * e / var;
    f.max_distance = std::max(f.max_distance, std::abs(e));
    ++used;
  }
  if (!(stt > 0)) return f;
  Eigen::Matrix2d c;
  c << vcc / (sw * sw), vcp / (sw * stt), vcp / (sw * stt), vpp / (stt * stt);
  Eigen::Matrix2d j;
  j << 1.0, tbar, 0.0, 1.0;
  f.covariance = j * c * j.transpose();
  // Points scattering more than their claimed noise (clutter, a slightly bent wall) make the
  // fit less certain than the noise model says.
  if (used > 2) f.covariance *= std::max(1.0, chi2 / (used - 2));
  f.mse = sq / sw;
  f.valid = f.covariance.allFinite();
  return f;
}

LineSegment transformSegment(const LineSegment& s, const Pose2& pose) {
  LineSegment out = s;
  double phi = s.line.phi + pose.theta;
  double r = s.line.r + pose.x * std::cos(phi) + pose.y * std::sin(phi);
  Eigen::Matrix2d j;
  j << 1.0, -pose.x * std::sin(phi) + pose.y * std::cos(phi), 0.0, 1.0;
  if (r < 0) j.row(0) *= -1.0;
  normalizeLine(r, phi);
  out.line.r = r;
  out.line.phi = phi;
  out.line.covariance = j * s.line.covariance * j.transpose();
  out.p0 = pose * s.p0;
  out.p1 = pose * s.p1;
  return out;
}

LineExtractor::LineExtractor(LineExtractorOptions o) : options_(o) {
  ConfigCheck()
      .positive("range_sigma", o.range_sigma)
      .nonNegative("range_sigma_rel", o.range_sigma_rel)
      .positive("breakpoint_distance", o.breakpoint_distance)
      .nonNegative("breakpoint_factor", o.breakpoint_factor)
      .positive("split_mse", o.split_mse)
      .positive("split_max_distance", o.split_max_distance)
      .require(o.fuzzy_iterations >= 0, "fuzzy_iterations", "must be >= 0", o.fuzzy_iterations)
      .require(std::isfinite(o.fuzzy_exponent) && o.fuzzy_exponent > 1, "fuzzy_exponent",
               "must be > 1", o.fuzzy_exponent)
      .positive("fuzzy_far_distance", o.fuzzy_far_distance)
      .require(o.min_points >= 2, "min_points", "must be >= 2", o.min_points)
      .nonNegative("min_length", o.min_length)
      .nonNegative("merge_angle", o.merge_angle)
      .nonNegative("merge_distance", o.merge_distance)
      .positive("max_range", o.max_range)
      .throwIfBad();
}

LineFit LineExtractor::fit(std::span<const Eigen::Vector2d> points, std::span<const double> sigmas,
                           int begin, int end) const {
  const auto b = static_cast<std::size_t>(begin), len = static_cast<std::size_t>(end - begin);
  return fitLineWtls(points.subspan(b, len), {}, options_.range_sigma,
                     sigmas.empty() ? sigmas : sigmas.subspan(b, len));
}

bool LineExtractor::needsSplit(const LineFit& f) const {
  return !f.valid || f.mse > options_.split_mse || f.max_distance > options_.split_max_distance;
}

int LineExtractor::fuzzySplit(std::span<const Eigen::Vector2d> points,
                              std::span<const double> sigmas, int begin, int end) const {
  const int n = end - begin;
  if (n < 4) return -1;
  // Start from the classic IEPF split: the point farthest from the chord of the run.
  const Eigen::Vector2d a = points[begin], c = points[end - 1];
  const Eigen::Vector2d chord = c - a;
  const double chord_len = chord.norm();
  int k0 = begin + n / 2;
  if (chord_len > 0) {
    double best = -1;
    for (int j = begin + 1; j < end - 1; ++j) {
      const Eigen::Vector2d d = points[j] - a;
      const double dist = std::abs(chord.x() * d.y() - chord.y() * d.x()) / chord_len;
      if (dist > best) {
        best = dist;
        k0 = j;
      }
    }
  }
  k0 = std::clamp(k0, begin + 2, end - 2);
  if (!options_.split_fuzzy) return k0;

  LineFit lines[2] = {fit(points, sigmas, begin, k0 + 1), fit(points, sigmas, k0, end)};
  if (!lines[0].valid || !lines[1].valid) return k0;
  const auto span_points =
      points.subspan(static_cast<std::size_t>(begin), static_cast<std::size_t>(n));
  std::vector<double> u[2] = {std::vector<double>(n), std::vector<double>(n)};
  std::vector<double> wts(n);
  const double m = options_.fuzzy_exponent, inv_m1 = 1.0 / (m - 1.0);
  const double far2 = options_.fuzzy_far_distance * options_.fuzzy_far_distance;
  const auto sigmaOf = [&](int j) {
    return sigmas.empty() ? options_.range_sigma : sigmas[static_cast<std::size_t>(begin + j)];
  };
  for (int it = 0; it < options_.fuzzy_iterations; ++it) {
    // Memberships u_ij ∝ (1/d²)^(1/(m−1)), normalised over the two lines plus a noise term
    // (the penalty for points far from both lines): such points pull on neither fit.
    for (int j = 0; j < n; ++j) {
      const double floor2 = sigmaOf(j) * sigmaOf(j);
      double g[2];
      for (int i = 0; i < 2; ++i) {
        const double d = lines[i].distance(span_points[j]);
        g[i] = std::pow(1.0 / std::max(d * d, floor2), inv_m1);
      }
      const double noise = std::pow(1.0 / far2, inv_m1);
      const double sum = g[0] + g[1] + noise;
      u[0][j] = g[0] / sum;
      u[1][j] = g[1] / sum;
    }
    bool ok = true;
    LineFit next[2];
    for (int i = 0; i < 2; ++i) {
      for (int j = 0; j < n; ++j) wts[j] = std::pow(u[i][j], m);
      next[i] = fitLineWtls(span_points, wts, options_.range_sigma,
                            sigmas.empty() ? sigmas
                                           : sigmas.subspan(static_cast<std::size_t>(begin),
                                                            static_cast<std::size_t>(n)));
      ok = ok && next[i].valid;
    }
    if (!ok) break;
    const double change = std::abs(angleDiff(next[0].phi, lines[0].phi)) +
                          std::abs(angleDiff(next[1].phi, lines[1].phi));
    lines[0] = next[0];
    lines[1] = next[1];
    if (change < 1e-6) break;
  }
  // Each point goes to its nearer line; the segments must stay contiguous in scan order, so
  // pick the cut that agrees with most of these labels (line A before B, or B before A).
  std::vector<int> prefix_a(n + 1, 0);
  for (int j = 0; j < n; ++j) {
    const bool to_a =
        std::abs(lines[0].distance(span_points[j])) <= std::abs(lines[1].distance(span_points[j]));
    prefix_a[j + 1] = prefix_a[j] + (to_a ? 1 : 0);
  }
  const int total_a = prefix_a[n];
  int best_k = k0 - begin, best_score = -1;
  for (int k = 2; k <= n - 2; ++k) {
    const int a_first = prefix_a[k] + ((n - k) - (total_a - prefix_a[k]));
    const int b_first = (k - prefix_a[k]) + (total_a - prefix_a[k]);
    const int score = std::max(a_first, b_first);
    if (score > best_score) {
      best_score = score;
      best_k = k;
    }
  }
  return begin + best_k;
}

std::vector<LineSegment> LineExtractor::extract(const grid::RangeScan& scan,
                                                LineExtractionStats* stats) const {
  LineExtractionStats local;
  std::vector<Eigen::Vector2d> points;
  std::vector<double> sigmas;
  points.reserve(scan.ranges.size());
  sigmas.reserve(scan.ranges.size());
  if (!std::isfinite(scan.angle_min) || !std::isfinite(scan.angle_increment)) {
    local.invalid_beams = scan.ranges.size();
    if (stats) *stats = local;
    return {};
  }
  // Breakpoints need the beam spacing, which the point list alone no longer has: cut clusters
  // here and extract each one separately.
  std::vector<LineSegment> out;
  std::vector<double> ranges;
  const auto flush = [&] {
    if (points.empty()) return;
    LineExtractionStats part;
    auto segs = extract(points, sigmas, &part);
    local.points += part.points;
    local.clusters += part.clusters;
    local.splits += part.splits;
    local.merges += part.merges;
    local.dropped_segments += part.dropped_segments;
    for (auto& s : segs) {
      s.first += static_cast<int>(ranges.size() - points.size());
      s.last += static_cast<int>(ranges.size() - points.size());
      out.push_back(s);
    }
    points.clear();
    sigmas.clear();
  };
  const double max_range = std::min(options_.max_range, scan.range_max);
  double prev_angle = 0, prev_range = 0;
  for (std::size_t k = 0; k < scan.ranges.size(); ++k) {
    const double rho = scan.ranges[k];
    if (std::isnan(rho) || rho < scan.range_min || rho < 0) {
      ++local.invalid_beams;
      continue;
    }
    if (!std::isfinite(rho) || rho >= max_range) {
      ++local.no_return;
      continue;
    }
    const double angle = scan.angle_min + static_cast<double>(k) * scan.angle_increment;
    const Eigen::Vector2d p(rho * std::cos(angle), rho * std::sin(angle));
    if (!points.empty()) {
      const double gap = (p - points.back()).norm();
      const double spacing = std::min(rho, prev_range) * std::abs(angle - prev_angle);
      if (gap > std::max(options_.breakpoint_distance, options_.breakpoint_factor * spacing))
        flush();
    }
    points.push_back(p);
    sigmas.push_back(options_.range_sigma + options_.range_sigma_rel * rho);
    ranges.push_back(rho);
    prev_angle = angle;
    prev_range = rho;
  }
  flush();
  if (stats) *stats = local;
  return out;
}

std::vector<LineSegment> LineExtractor::extract(std::span<const Eigen::Vector2d> points,
                                                std::span<const double> sigmas,
                                                LineExtractionStats* stats) const {
  LineExtractionStats local;
  std::vector<LineSegment> out;
  const int n = static_cast<int>(points.size());
  if (!sigmas.empty() && sigmas.size() != points.size()) sigmas = {};
  local.points = points.size();
  if (n > 0) local.clusters = 1;

  // Split (AIEPF step 2/3): runs are processed in scan order, a run that needs splitting is
  // replaced by its two halves.
  struct Run {
    int begin, end;
  };
  std::vector<Run> stack{{0, n}};
  std::vector<Run> done;
  while (!stack.empty()) {
    const Run run = stack.back();
    stack.pop_back();
    const int len = run.end - run.begin;
    if (len < 2) continue;
    const LineFit f = fit(points, sigmas, run.begin, run.end);
    if (needsSplit(f) && len >= 4) {
      const int k = fuzzySplit(points, sigmas, run.begin, run.end);
      if (k > run.begin && k < run.end) {
        ++local.splits;
        stack.push_back({k, run.end});  // LIFO: the first half is processed first
        stack.push_back({run.begin, k});
        continue;
      }
    }
    if (needsSplit(f)) continue;  // cannot be split further and is not a line: clutter
    done.push_back(run);
  }

  // Merge collinear neighbours: adjacent runs whose joint fit is still a single line.
  const auto mergeable = [&](const Run& a, const Run& b, LineFit& joint) {
    if (a.end != b.begin) return false;
    const LineFit fa = fit(points, sigmas, a.begin, a.end);
    const LineFit fb = fit(points, sigmas, b.begin, b.end);
    if (std::abs(angleDiff(fa.phi, fb.phi)) > options_.merge_angle ||
        std::abs(fa.r - fb.r) > options_.merge_distance)
      return false;
    joint = fit(points, sigmas, a.begin, b.end);
    return !needsSplit(joint);
  };
  bool merged = true;
  while (merged) {
    merged = false;
    for (std::size_t i = 0; i + 1 < done.size(); ++i) {
      LineFit joint;
      if (mergeable(done[i], done[i + 1], joint)) {
        done[i].end = done[i + 1].end;
        done.erase(done.begin() + static_cast<std::ptrdiff_t>(i) + 1);
        ++local.merges;
        merged = true;
      }
    }
  }

  for (const Run& run : done) {
    LineSegment s;
    s.line = fit(points, sigmas, run.begin, run.end);
    s.first = run.begin;
    s.last = run.end - 1;
    const Eigen::Vector2d foot = s.line.r * s.line.normal();
    const Eigen::Vector2d dir = s.line.direction();
    s.p0 = foot + dir * points[run.begin].dot(dir);
    s.p1 = foot + dir * points[run.end - 1].dot(dir);
    if (!s.line.valid || s.points() < options_.min_points || s.length() < options_.min_length) {
      ++local.dropped_segments;
      continue;
    }
    out.push_back(s);
  }
  if (stats) *stats = local;
  return out;
}

}  // namespace tessera::line_slam
