// MonteCarloLocalizer: odometry motion model, likelihood-field weights, KLD resampling with
// random-particle recovery, cluster estimate.
#include <tessera/localization/monte_carlo_localizer.hpp>

#include <tessera/config/config_check.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

namespace tessera::localization {

void MonteCarloOptions::validate() const {
  ConfigCheck()
      .require(min_particles >= 1, "min_particles", "must be >= 1", min_particles)
      .require(max_particles >= min_particles, "max_particles", "must be >= min_particles",
               max_particles)
      .positive("kld_error", kld_error)
      .require(global_particles >= 0 && global_particles <= 1000000, "global_particles",
               "must be in [0, 1e6]", global_particles)
      .require(min_ess >= 0 && min_ess < 1, "min_ess", "must be in [0, 1)", min_ess)
      .nonNegative("kld_z", kld_z)
      .positive("bin_xy", bin_xy)
      .positive("bin_theta", bin_theta)
      .nonNegative("update_min_d", update_min_d)
      .nonNegative("update_min_a", update_min_a)
      .require(max_beams >= 1, "max_beams", "must be >= 1", max_beams)
      .require(recovery_alpha_slow >= 0 && recovery_alpha_slow <= 1, "recovery_alpha_slow",
               "must be in [0, 1]", recovery_alpha_slow)
      .require(recovery_alpha_fast >= recovery_alpha_slow && recovery_alpha_fast <= 1,
               "recovery_alpha_fast", "must be in [recovery_alpha_slow, 1]", recovery_alpha_fast)
      .require(lost_inlier_fraction >= 0 && lost_inlier_fraction <= 1, "lost_inlier_fraction",
               "must be in [0, 1]", lost_inlier_fraction)
      .positive("inlier_distance", inlier_distance)
      .require(lost_updates >= 1, "lost_updates", "must be >= 1", lost_updates)
      .nonNegative("refine_step", refine_step)
      .positive("refine_max_shift", refine_max_shift)
      .nonNegative("motion.alpha1", motion.alpha1)
      .nonNegative("motion.alpha2", motion.alpha2)
      .nonNegative("motion.alpha3", motion.alpha3)
      .nonNegative("motion.alpha4", motion.alpha4)
      .throwIfBad("monte carlo localisation");
}

int kldSampleCount(int k, double epsilon, double z) {
  if (k <= 1) return 1;
  const double a = 2.0 / (9.0 * (k - 1));
  const double b = 1.0 - a + std::sqrt(a) * z;
  return static_cast<int>(std::ceil((k - 1) / (2.0 * epsilon) * b * b * b));
}

MonteCarloLocalizer::MonteCarloLocalizer(const grid::OccupancyMap& map, double range_max,
                                         const MonteCarloOptions& options)
    : options_(options), field_(map, range_max, options.field), rng_(options.seed) {
  options_.validate();
  free_cells_ = freeCells(field_);
}

std::vector<Eigen::Vector2i> MonteCarloLocalizer::freeCells(const LikelihoodField& field) {
  std::vector<Eigen::Vector2i> out;
  const grid::OccupancyMap& m = field.map();
  for (int row = 0; row < m.height; ++row)
    for (int col = 0; col < m.width; ++col)
      if (field.isFree(m.cellCenter(col, row))) out.emplace_back(col, row);
  return out;
}

void MonteCarloLocalizer::setMap(const grid::OccupancyMap& map) {
  LikelihoodField field(map, field_.rangeMax(), options_.field);  // throws before any change
  free_cells_ = freeCells(field);
  field_ = std::move(field);
}

Pose2 MonteCarloLocalizer::randomFreePose() {
  std::uniform_int_distribution<std::size_t> cell(0, free_cells_.size() - 1);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const Eigen::Vector2i c = free_cells_[cell(rng_)];
  const grid::OccupancyMap& m = field_.map();
  const Eigen::Vector2d p = m.origin * Eigen::Vector2d((c.x() + unit(rng_)) * m.resolution,
                                                       (c.y() + unit(rng_)) * m.resolution);
  return {p.x(), p.y(), (2 * unit(rng_) - 1) * std::numbers::pi};
}

void MonteCarloLocalizer::initialise(const Pose2& mean, const Eigen::Matrix3d& covariance) {
  if (!mean.isFinite() || !covariance.allFinite())
    throw std::invalid_argument("monte carlo localisation: initial pose or covariance not finite");
  Eigen::LLT<Eigen::Matrix3d> llt(0.5 * (covariance + covariance.transpose()));
  const Eigen::Matrix3d l =
      llt.info() == Eigen::Success
          ? Eigen::Matrix3d(llt.matrixL())
          : Eigen::Matrix3d(covariance.diagonal().cwiseAbs().cwiseSqrt().asDiagonal());
  std::normal_distribution<double> n01(0.0, 1.0);
  particles_.assign(static_cast<std::size_t>(options_.max_particles), {});
  for (Particle& p : particles_) {
    const Eigen::Vector3d d = l * Eigen::Vector3d(n01(rng_), n01(rng_), n01(rng_));
    p.pose = Pose2(mean.x + d.x(), mean.y + d.y(), mean.theta + d.z());
    p.weight = 1.0 / options_.max_particles;
  }
  last_odom_.reset();
  refined_.reset();
  w_slow_ = w_fast_ = 0;
}

void MonteCarloLocalizer::initialiseGlobal() {
  if (free_cells_.empty())
    throw std::invalid_argument("monte carlo localisation: the map has no free cell");
  const int n = options_.global_particles > 0 ? options_.global_particles : options_.max_particles;
  particles_.assign(static_cast<std::size_t>(n), {});
  for (Particle& p : particles_) {
    p.pose = randomFreePose();
    p.weight = 1.0 / n;
  }
  last_odom_.reset();
  refined_.reset();
  w_slow_ = w_fast_ = 0;
}

double MonteCarloLocalizer::randomShare() const {
  if (options_.recovery_alpha_slow <= 0 || w_slow_ <= 0) return 0.0;
  return std::max(0.0, 1.0 - w_fast_ / w_slow_);
}

bool MonteCarloLocalizer::update(const Pose2& odom, std::span<const Eigen::Vector2d> points,
                                 bool force) {
  if (particles_.empty() || !odom.isFinite()) return false;
  const Pose2 last = last_odom_.value_or(odom);
  const Pose2 delta = between(last, odom);
  const double moved = std::hypot(delta.x, delta.y);
  if (last_odom_ && !force && moved < options_.update_min_d &&
      std::abs(delta.theta) < options_.update_min_a)
    return false;

  // Beams: finite endpoints, at most max_beams of them, evenly spread.
  std::vector<Eigen::Vector2d> beams;
  const std::size_t stride =
      std::max<std::size_t>(1, (points.size() + options_.max_beams - 1) / options_.max_beams);
  for (std::size_t i = 0; i < points.size(); i += stride)
    if (points[i].allFinite()) beams.push_back(points[i]);

  // Motion: rotation, translation, rotation in the odometry frame, each with noise.
  const double rot1 =
      moved < 0.01 ? 0.0 : angleDiff(std::atan2(odom.y - last.y, odom.x - last.x), last.theta);
  const double rot2 = angleDiff(delta.theta, rot1);
  // Driving backwards is a small rotation, not a half turn, for the noise.
  const double r1 = std::min(std::abs(rot1), std::abs(angleDiff(rot1, std::numbers::pi)));
  const double r2 = std::min(std::abs(rot2), std::abs(angleDiff(rot2, std::numbers::pi)));
  const MotionNoise& a = options_.motion;
  std::normal_distribution<double> n01(0.0, 1.0);
  const double s_rot1 = std::sqrt(a.alpha1 * r1 * r1 + a.alpha2 * moved * moved);
  const double s_trans = std::sqrt(a.alpha3 * moved * moved + a.alpha4 * (r1 * r1 + r2 * r2));
  const double s_rot2 = std::sqrt(a.alpha1 * r2 * r2 + a.alpha2 * moved * moved);
  for (Particle& p : particles_) {
    const double h1 = rot1 - s_rot1 * n01(rng_);
    const double t = moved - s_trans * n01(rng_);
    const double h2 = rot2 - s_rot2 * n01(rng_);
    const double th = p.pose.theta + h1;
    p.pose = Pose2(p.pose.x + t * std::cos(th), p.pose.y + t * std::sin(th), th + h2);
  }
  last_odom_ = odom;
  refined_.reset();                // the particles moved: an earlier refinement no longer applies
  if (beams.empty()) return true;  // moved, nothing to weigh with

  std::vector<double> log_l(particles_.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, particles_.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i < r.end(); ++i)
                        log_l[i] = field_.logLikelihood(particles_[i].pose, beams);
                    });
  // The fit: how well the best particle explains the scan, as its per-beam geometric mean
  // likelihood (independent of the beam count). The set's average would fall with every random
  // particle injected and so call for more of them.
  const auto best_it = std::max_element(log_l.begin(), log_l.end());
  const double best = *best_it;
  const double fit = std::exp(best / static_cast<double>(beams.size()));
  {
    const Pose2& b = particles_[static_cast<std::size_t>(best_it - log_l.begin())].pose;
    std::size_t inliers = 0;
    for (const Eigen::Vector2d& e : beams)
      if (field_.distance(b * e) <= options_.inlier_distance) ++inliers;
    inlier_fraction_ = static_cast<double>(inliers) / static_cast<double>(beams.size());
  }
  // Lost: re-spread, unless the set is still a spread one converging (it fits nowhere yet).
  const bool spread_set = static_cast<int>(particles_.size()) > options_.max_particles;
  lost_streak_ = options_.lost_inlier_fraction > 0 &&
                         inlier_fraction_ < options_.lost_inlier_fraction && !spread_set
                     ? lost_streak_ + 1
                     : 0;
  if (lost_streak_ >= options_.lost_updates && !free_cells_.empty()) {
    initialiseGlobal();
    last_odom_ = odom;  // the next update moves the new set by the motion from here
    lost_streak_ = 0;
    ++relocalisations_;
    ++updates_;
    return true;
  }
  if (w_slow_ == 0 && w_fast_ == 0) w_slow_ = w_fast_ = fit;
  w_slow_ += options_.recovery_alpha_slow * (fit - w_slow_);
  w_fast_ += options_.recovery_alpha_fast * (fit - w_fast_);

  // Tempering (min_ess > 0): the largest β in (0, 1] whose weights w_i · L_i^β keep an
  // effective sample size of at least min_ess · N, found by bisection (the ESS falls as β grows).
  const auto weightsFor = [&](double beta, std::vector<double>& w) {
    double total = 0, squares = 0;
    for (std::size_t i = 0; i < particles_.size(); ++i)
      total += w[i] = particles_[i].weight * std::exp(beta * (log_l[i] - best));
    for (double& x : w) {
      x /= total;
      squares += x * x;
    }
    return 1.0 / squares;  // ESS
  };
  std::vector<double> w(particles_.size());
  beta_ = 1.0;
  const double target = options_.min_ess * static_cast<double>(particles_.size());
  // Only while the set is larger than max_particles, i.e. still a global start's spread set:
  // a tracking set is not tempered (it would follow the scans more loosely).
  if (options_.min_ess > 0 && spread_set && weightsFor(1.0, w) < target) {
    double lo = 0.0, hi = 1.0;
    for (int k = 0; k < 30; ++k) {
      const double mid = 0.5 * (lo + hi);
      (weightsFor(mid, w) >= target ? lo : hi) = mid;
    }
    beta_ = std::max(lo, 1e-6);
  }
  weightsFor(beta_, w);
  for (std::size_t i = 0; i < particles_.size(); ++i) particles_[i].weight = w[i];
  resample();
  if (options_.refine_step > 0 && !spread_set) refine(points);
  ++updates_;
  return true;
}

void MonteCarloLocalizer::refine(std::span<const Eigen::Vector2d> points) {
  std::vector<Eigen::Vector2d> beams;
  beams.reserve(points.size());
  for (const Eigen::Vector2d& p : points)
    if (p.allFinite()) beams.push_back(p);
  if (beams.empty()) return;
  const Pose2 mean = clusterEstimate().pose;
  Pose2 best = mean;
  double best_ll = field_.logLikelihood(best, beams);
  double step = options_.refine_step;
  // Heading steps of step/2 rad per metre: a 0.05 m step turns by 0.025 rad, which moves a beam
  // endpoint 5 m away by about as much as the translation step.
  for (int level = 0; level < 5; ++level, step *= 0.5) {
    const double moves[6][3] = {{step, 0, 0},  {-step, 0, 0},      {0, step, 0},
                                {0, -step, 0}, {0, 0, step * 0.5}, {0, 0, -step * 0.5}};
    for (int iteration = 0; iteration < 20; ++iteration) {
      int chosen = -1;
      double chosen_ll = best_ll;
      for (int m = 0; m < 6; ++m) {
        const Pose2 candidate(best.x + moves[m][0], best.y + moves[m][1], best.theta + moves[m][2]);
        const double ll = field_.logLikelihood(candidate, beams);
        if (ll > chosen_ll) {
          chosen_ll = ll;
          chosen = m;
        }
      }
      if (chosen < 0) break;
      best = Pose2(best.x + moves[chosen][0], best.y + moves[chosen][1],
                   best.theta + moves[chosen][2]);
      best_ll = chosen_ll;
    }
  }
  const double shift = std::hypot(best.x - mean.x, best.y - mean.y);
  if (shift > options_.refine_max_shift) {
    ++refinements_refused_;
    return;
  }
  ++refinements_;
  last_refinement_shift_ = shift;
  // The whole cloud moves rigidly with its mean (each particle keeps its pose relative to the
  // mean), so its spread, the filter's uncertainty, stays what it was.
  if (options_.refine_particles)
    for (Particle& p : particles_) p.pose = best * between(mean, p.pose);
  refined_ = best;
}

namespace {

struct BinKey {
  std::int64_t operator()(const Pose2& p, double bxy, double bth) const {
    const auto x = static_cast<std::int64_t>(std::floor(p.x / bxy)) & 0xFFFFF;
    const auto y = static_cast<std::int64_t>(std::floor(p.y / bxy)) & 0xFFFFF;
    const auto t =
        static_cast<std::int64_t>(std::floor((p.theta + std::numbers::pi) / bth)) & 0xFFF;
    return (x << 32) | (y << 12) | t;
  }
};

}  // namespace

void MonteCarloLocalizer::resample() {
  const double share = randomShare();
  std::vector<double> cumulative(particles_.size());
  double acc = 0;
  for (std::size_t i = 0; i < particles_.size(); ++i) cumulative[i] = acc += particles_[i].weight;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Particle> next;
  // While tempered, the set may stay as large as it is (a global start shrinks as it converges).
  const int cap = beta_ < 1.0
                      ? std::max(options_.max_particles, static_cast<int>(particles_.size()))
                      : options_.max_particles;
  next.reserve(static_cast<std::size_t>(cap));
  std::unordered_set<std::int64_t> bins;
  int needed = options_.min_particles;
  while (static_cast<int>(next.size()) < std::max(needed, options_.min_particles) &&
         static_cast<int>(next.size()) < cap) {
    Pose2 pose;
    if (share > 0 && !free_cells_.empty() && unit(rng_) < share) {
      pose = randomFreePose();
    } else {
      const auto it = std::lower_bound(cumulative.begin(), cumulative.end(), unit(rng_) * acc);
      pose = particles_[static_cast<std::size_t>(std::min<std::ptrdiff_t>(
                            it - cumulative.begin(),
                            static_cast<std::ptrdiff_t>(particles_.size()) - 1))]
                 .pose;
    }
    next.push_back({pose, 0});
    if (bins.insert(BinKey{}(pose, options_.bin_xy, options_.bin_theta)).second)
      needed = kldSampleCount(static_cast<int>(bins.size()), options_.kld_error, options_.kld_z);
  }
  for (Particle& p : next) p.weight = 1.0 / static_cast<double>(next.size());
  particles_ = std::move(next);
}

PoseEstimate MonteCarloLocalizer::estimate() const {
  PoseEstimate out = clusterEstimate();
  if (refined_) out.pose = *refined_;
  return out;
}

PoseEstimate MonteCarloLocalizer::clusterEstimate() const {
  PoseEstimate out;
  if (particles_.empty()) return out;
  const double bxy = options_.bin_xy, bth = options_.bin_theta;
  const int theta_bins = static_cast<int>(std::ceil(2 * std::numbers::pi / bth));
  auto cellOf = [&](const Pose2& p) {
    return Eigen::Vector3i(
        static_cast<int>(std::floor(p.x / bxy)), static_cast<int>(std::floor(p.y / bxy)),
        std::clamp(static_cast<int>(std::floor((p.theta + std::numbers::pi) / bth)), 0,
                   theta_bins - 1));
  };
  auto key = [](const Eigen::Vector3i& c) {
    return (static_cast<std::int64_t>(c.x() & 0xFFFFF) << 32) |
           (static_cast<std::int64_t>(c.y() & 0xFFFFF) << 12) | (c.z() & 0xFFF);
  };
  std::unordered_map<std::int64_t, int> cluster_of;  // bin -> cluster (-1 = not yet labelled)
  std::vector<Eigen::Vector3i> bin_cells;
  for (const Particle& p : particles_) {
    const Eigen::Vector3i c = cellOf(p.pose);
    if (cluster_of.emplace(key(c), -1).second) bin_cells.push_back(c);
  }
  // Label connected bins (26-neighbourhood, heading wrapping around).
  int clusters = 0;
  for (const Eigen::Vector3i& seed : bin_cells) {
    if (cluster_of[key(seed)] >= 0) continue;
    std::vector<Eigen::Vector3i> stack{seed};
    cluster_of[key(seed)] = clusters;
    while (!stack.empty()) {
      const Eigen::Vector3i c = stack.back();
      stack.pop_back();
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dt = -1; dt <= 1; ++dt) {
            const Eigen::Vector3i n(c.x() + dx, c.y() + dy, (c.z() + dt + theta_bins) % theta_bins);
            const auto it = cluster_of.find(key(n));
            if (it == cluster_of.end() || it->second >= 0) continue;
            it->second = clusters;
            stack.push_back(n);
          }
    }
    ++clusters;
  }
  std::vector<double> weight(static_cast<std::size_t>(clusters), 0.0);
  std::vector<int> label(particles_.size());
  for (std::size_t i = 0; i < particles_.size(); ++i) {
    label[i] = cluster_of[key(cellOf(particles_[i].pose))];
    weight[static_cast<std::size_t>(label[i])] += particles_[i].weight;
  }
  const int best =
      static_cast<int>(std::max_element(weight.begin(), weight.end()) - weight.begin());
  double w = 0, x = 0, y = 0, s = 0, c = 0;
  for (std::size_t i = 0; i < particles_.size(); ++i) {
    if (label[i] != best) continue;
    const Particle& p = particles_[i];
    w += p.weight;
    x += p.weight * p.pose.x;
    y += p.weight * p.pose.y;
    s += p.weight * std::sin(p.pose.theta);
    c += p.weight * std::cos(p.pose.theta);
  }
  out.pose = Pose2(x / w, y / w, std::atan2(s, c));
  for (std::size_t i = 0; i < particles_.size(); ++i) {
    if (label[i] != best) continue;
    const Particle& p = particles_[i];
    const Eigen::Vector3d d(p.pose.x - out.pose.x, p.pose.y - out.pose.y,
                            angleDiff(p.pose.theta, out.pose.theta));
    out.covariance += p.weight / w * d * d.transpose();
  }
  out.odom = last_odom_.value_or(Pose2());
  out.cluster_weight = w;
  out.clusters = clusters;
  return out;
}

}  // namespace tessera::localization
