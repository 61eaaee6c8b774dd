// Rbpf (rbpf.hpp; docs/algorithms.md#rbpf-submaps): motion sampling, two-stage scan matching with
// recovery, the proposal and weights, resampling, the best particle and the online tracking.
// Longer than ~600 lines on purpose: these steps share the filter's private state and its
// invariants (particle maps shared copy-on-write, weights normalised at every update), and split
// over files no part could be read on its own.
#include <tessera/laser_slam/rbpf.hpp>

#include <tbb/parallel_for.h>

#include <Eigen/Cholesky>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <stdexcept>
#include <string>

namespace tessera::laser_slam {
namespace {

using tessera::Pose2;

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("rbpf: " + what);
}

// SplitMix64 finaliser: decorrelates the per-particle random streams derived from one seed.
std::uint64_t mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

std::mt19937_64 streamFor(std::uint64_t seed, std::uint64_t update, std::uint64_t particle) {
  return std::mt19937_64(mix(seed ^ mix(update * 0x100000001b3ULL + particle)));
}

Pose2 sampleGaussian(const Pose2& mean, const Eigen::Matrix3d& cov, std::mt19937_64& rng) {
  Eigen::LLT<Eigen::Matrix3d> llt(cov);
  Eigen::Matrix3d l;
  if (llt.info() == Eigen::Success) {
    l = llt.matrixL();
  } else {
    // Not positive definite (degenerate fit): fall back to the per-axis spread.
    l = cov.diagonal().cwiseMax(0.0).cwiseSqrt().asDiagonal();
  }
  std::normal_distribution<double> n01;
  const Eigen::Vector3d z(n01(rng), n01(rng), n01(rng));
  const Eigen::Vector3d d = l * z;
  return {mean.x + d.x(), mean.y + d.y(), mean.theta + d.z()};
}

/// A covariance over (x, y, θ) stated in the robot frame at `frame`, expressed in the map.
Eigen::Matrix3d inMapFrame(const Eigen::Matrix3d& local, const Pose2& frame) {
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  r.topLeftCorner<2, 2>() = frame.rotation();
  return r * local * r.transpose();
}

/// exp(-½ (|Δxy|² / σ_linear² + Δθ² / σ_angular²)) between two poses.
double poseKernel(const Pose2& a, const Pose2& b, double sigma_linear, double sigma_angular) {
  const double dx = (a.x - b.x) / sigma_linear;
  const double dy = (a.y - b.y) / sigma_linear;
  const double dt = tessera::angleDiff(a.theta, b.theta) / sigma_angular;
  return std::exp(-0.5 * (dx * dx + dy * dy + dt * dt));
}

}  // namespace

std::size_t selectBestParticle(std::span<const Pose2> poses, std::span<const double> weights,
                               std::span<const double> tie_break, double sigma_linear,
                               double sigma_angular) {
  const std::size_t n = poses.size();
  std::vector<double> support(n, 0.0);
  if (sigma_linear > 0 && sigma_angular > 0) {
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < n; ++j)
        support[i] += weights[j] * poseKernel(poses[i], poses[j], sigma_linear, sigma_angular);
  }
  // Supports within a relative 1e-9 are ties (copies of one particle, or the disabled kernel).
  std::size_t best = 0;
  for (std::size_t i = 1; i < n; ++i) {
    const double tol = 1e-9 * std::max(support[i], support[best]);
    if (support[i] > support[best] + tol ||
        (support[i] >= support[best] - tol && tie_break[i] > tie_break[best]))
      best = i;
  }
  return best;
}

Pose2 kernelMean(std::span<const Pose2> poses, std::span<const double> weights, const Pose2& centre,
                 double sigma_linear, double sigma_angular) {
  if (!(sigma_linear > 0 && sigma_angular > 0)) return centre;
  double total = 0, x = 0, y = 0, dtheta = 0;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const double w = weights[i] * poseKernel(poses[i], centre, sigma_linear, sigma_angular);
    total += w;
    x += w * poses[i].x;
    y += w * poses[i].y;
    dtheta += w * tessera::angleDiff(poses[i].theta, centre.theta);
  }
  if (!(total > 0)) return centre;
  return Pose2{x / total, y / total, centre.theta + dtheta / total};
}

std::vector<std::size_t> systematicResample(const std::vector<double>& weights, double u0) {
  const std::size_t n = weights.size();
  std::vector<std::size_t> out;
  out.reserve(n);
  double total = 0.0;
  for (double w : weights) total += w;
  if (n == 0 || !(total > 0) || !std::isfinite(total)) {
    for (std::size_t k = 0; k < n; ++k) out.push_back(k);  // nothing to prefer: keep all
    return out;
  }
  const double step = total / static_cast<double>(n);
  double u = u0 * total;
  double cumulative = weights[0];
  std::size_t i = 0;
  for (std::size_t k = 0; k < n; ++k, u += step) {
    while (cumulative < u && i + 1 < n) cumulative += weights[++i];
    out.push_back(i);
  }
  return out;
}

namespace {
// Invalid values are left out here, so that the constructor's checks name the option.
tessera::scan_matching::ScanMatcherOptions trackingMatcherOptions(const RbpfOptions& o) {
  tessera::scan_matching::ScanMatcherOptions t = o.matcher;
  if (std::isfinite(o.track_linear_step) && o.track_linear_step > 0)
    t.linear_step = o.track_linear_step;
  if (std::isfinite(o.track_angular_step) && o.track_angular_step > 0)
    t.angular_step = o.track_angular_step;
  if (o.track_refinements > 0) t.refinements = o.track_refinements;
  return t;
}
}  // namespace

Rbpf::Rbpf(RbpfOptions options)
    : options_(std::move(options)),
      matcher_(options_.matcher),
      tracking_matcher_(trackingMatcherOptions(options_)) {
  const auto& o = options_;
  require(o.particles >= 1 && o.particles <= 100000,
          "particles must be in [1, 100000] (got " + std::to_string(o.particles) + ")");
  require(
      o.resample_threshold > 0 && o.resample_threshold <= 1,
      "resample_threshold must be in (0, 1] (got " + std::to_string(o.resample_threshold) + ")");
  require(std::isfinite(o.weight_divisor) && o.weight_divisor >= 0,
          "weight_divisor must be >= 0 (0 = the particle count)");
  require(std::isfinite(o.linear_update) && o.linear_update >= 0, "linear_update must be >= 0 [m]");
  require(std::isfinite(o.angular_update) && o.angular_update >= 0,
          "angular_update must be >= 0 [rad]");
  require(std::isfinite(o.temporal_update) && o.temporal_update >= 0,
          "temporal_update must be >= 0 [s] (0 disables)");
  const auto& m = o.motion;
  for (double v : {m.srr, m.srt, m.str, m.stt})
    require(std::isfinite(v) && v >= 0, "motion noise srr/srt/str/stt must be >= 0");
  // The grid validates its own options; fail here, at configuration, not at the first scan.
  tessera::grid::TiledGrid probe(o.grid);
  require(std::isfinite(o.handover_sigma_linear) && o.handover_sigma_linear >= 0 &&
              std::isfinite(o.handover_sigma_angular) && o.handover_sigma_angular >= 0,
          "handover_sigma_linear and handover_sigma_angular must be >= 0");
  require(std::isfinite(o.carry_over_distance) && o.carry_over_distance >= 0,
          "carry_over_distance must be a finite number of metres >= 0 (0: the last scan only)");
  require(std::isfinite(o.lost_match_fraction) && o.lost_match_fraction >= 0 &&
              o.lost_match_fraction < 1,
          "lost_match_fraction must be in [0, 1) (0 disables)");
  require(o.lost_updates >= 1, "lost_updates must be >= 1");
  require(std::isfinite(o.lost_sigma_linear) && o.lost_sigma_linear > 0 &&
              std::isfinite(o.lost_sigma_angular) && o.lost_sigma_angular > 0,
          "lost_sigma_linear and lost_sigma_angular must be finite and > 0");
  require(o.coarse_kernel_radius >= 0, "coarse_kernel_radius must be >= 0 (0 disables)");
  require(o.coarse_beam_step >= 1, "coarse_beam_step must be >= 1");
  require(std::isfinite(o.recovery_sigma) && o.recovery_sigma >= 0,
          "recovery_sigma must be >= 0 (0 disables)");
  require(std::isfinite(o.recovery_angular_step) && o.recovery_angular_step > 0,
          "recovery_angular_step must be > 0 [rad]");
  require(std::isfinite(o.best_support_linear) && o.best_support_linear >= 0,
          "best_support_linear must be >= 0 [m] (0: highest accumulated weight alone)");
  require(std::isfinite(o.best_support_angular) && o.best_support_angular >= 0,
          "best_support_angular must be >= 0 [rad] (0: highest accumulated weight alone)");
  require(std::isfinite(o.track_linear_step) && o.track_linear_step >= 0 &&
              std::isfinite(o.track_angular_step) && o.track_angular_step >= 0,
          "track_linear_step and track_angular_step must be >= 0 (0: the fine matcher's)");
  require(o.track_refinements >= 0, "track_refinements must be >= 0 (0: the fine matcher's)");
  require(std::isfinite(o.online_mean_linear) && o.online_mean_linear >= 0 &&
              std::isfinite(o.online_mean_angular) && o.online_mean_angular >= 0,
          "online_mean_linear and online_mean_angular must be >= 0 (0: the best particle's pose)");
  require(std::isfinite(o.min_overlap_fraction) && o.min_overlap_fraction >= 0 &&
              o.min_overlap_fraction <= 1,
          "min_overlap_fraction must be in [0, 1]");
  if (o.coarse_kernel_radius > 0) {
    tessera::scan_matching::ScanMatcherOptions coarse = o.matcher;
    coarse.kernel_radius = o.coarse_kernel_radius;
    coarse.beam_step = o.matcher.beam_step * o.coarse_beam_step;
    coarse.refinements = 2;  // only to get into the fine stage's basin
    coarse_matcher_.emplace(coarse);
  }
}

Eigen::Matrix3d Rbpf::motionCovariance(const Pose2& delta) const {
  const auto& m = options_.motion;
  const double trans = std::hypot(delta.x, delta.y);
  const double rot = std::abs(delta.theta);
  // A small floor keeps the prior proper when the robot barely moved (time-triggered updates).
  const double sx = m.srr * std::abs(delta.x) + m.srt * rot + 1e-3;
  const double sy = m.srr * std::abs(delta.y) + m.srt * rot + 1e-3;
  const double st = m.stt * rot + m.str * trans + 1e-3;
  return Eigen::Vector3d(sx * sx, sy * sy, st * st).asDiagonal();
}

RbpfStep Rbpf::addScan(double stamp_s, const tessera::grid::RangeScan& scan, const Pose2& mount,
                       const Pose2& odometry) {
  RbpfStep step;
  ++stats_.scans;
  if (!odometry.isFinite() || !mount.isFinite() || !std::isfinite(stamp_s)) {
    ++stats_.invalid_odometry;
    return step;
  }
  const tessera::scan_matching::ScanPoints points = matcher_.prepare(scan, mount);
  const bool usable = !points.endpoints.empty();
  if (usable) {
    last_ranges_.assign(scan.ranges.begin(), scan.ranges.end());
    last_scan_ = scan;
    last_scan_.ranges = last_ranges_;
    last_mount_ = mount;
  } else {
    ++stats_.unusable_scans;
    step.scan_unusable = true;
  }
  last_scan_usable_ = usable;

  if (!initialized_) {
    last_odometry_ = odometry;
    last_stamp_s_ = stamp_s;
    if (!usable) return step;
    initialize(stamp_s, scan, mount, odometry);
    step.updated = true;
    step.neff = particleCount();
    return step;
  }

  const Pose2 moved = tessera::between(last_odometry_, odometry);
  const double dist = std::hypot(moved.x, moved.y);
  travelled_since_update_ += dist;
  turned_since_update_ += std::abs(moved.theta);
  submap_travelled_ += dist;
  last_odometry_ = odometry;
  last_stamp_s_ = stamp_s;
  if (!usable) return step;  // keeps the gate armed for the next usable scan

  const bool gate =
      travelled_since_update_ >= options_.linear_update ||
      turned_since_update_ >= options_.angular_update ||
      (options_.temporal_update > 0 && stamp_s - update_stamp_s_ >= options_.temporal_update);
  if (!gate) {
    if (options_.track_between_updates) trackScan(scan, mount, points, odometry);
    return step;
  }

  ++update_index_;
  const tessera::scan_matching::ScanPoints coarse_points =
      coarse_matcher_ ? coarse_matcher_->prepare(scan, mount)
                      : tessera::scan_matching::ScanPoints{};
  const std::size_t failures =
      updateParticles(points, coarse_points, tessera::between(update_odometry_, odometry));
  step.updated = true;
  step.matched = failures < particles_.size();
  step.match_fraction = last_match_fraction_;
  stats_.match_fraction_min = std::min(stats_.match_fraction_min, last_match_fraction_);
  step.neff = normalizeWeights();
  if (step.neff < options_.resample_threshold * particleCount()) {
    resample();
    step.resampled = true;
    ++stats_.resamples;
  }
  step.suspect = last_match_fraction_ < options_.lost_match_fraction;
  if (step.suspect) {
    ++stats_.suspect_updates;
    step.lost = ++suspect_run_ >= options_.lost_updates;
    if (step.lost) ++stats_.lost;
  } else {
    suspect_run_ = 0;
    insertScan(scan, mount);
  }
  if (options_.carry_over_distance > 0 && !step.suspect) {
    KeptScan& kept =
        kept_.emplace_back(stamp_s, std::vector<float>(scan.ranges.begin(), scan.ranges.end()),
                           scan, mount, submap_travelled_);
    kept.scan.ranges = kept.ranges;  // its own copy (a vector's buffer survives moves)
    const auto old = std::find_if(kept_.begin(), kept_.end(), [&](const KeptScan& k) {
      return submap_travelled_ - k.path_m <= options_.carry_over_distance;
    });
    kept_.erase(kept_.begin(), old);
  }
  for (auto& p : particles_)
    p.node = std::make_shared<TrajectoryNode>(TrajectoryNode{stamp_s, p.pose, std::move(p.node)});
  best_ = bestIndex();
  update_odometry_ = odometry;
  resetTracking(odometry);
  update_stamp_s_ = stamp_s;
  travelled_since_update_ = 0.0;
  turned_since_update_ = 0.0;
  ++stats_.updates;
  // Sampled: walking every tile of every map at each update cost ~3 % of carmen_global's CPU.
  if (stats_.updates % kMapBytesEvery == 0) noteMapBytes();
  return step;
}

void Rbpf::initialize(double stamp_s, const tessera::grid::RangeScan& scan, const Pose2& mount,
                      const Pose2& odometry) {
  auto map = std::make_shared<tessera::grid::TiledGrid>(options_.grid);
  map->insertScan(scan, mount, options_.insert);  // robot at the submap origin
  auto node = std::make_shared<const TrajectoryNode>(TrajectoryNode{stamp_s, Pose2{}, nullptr});
  const double uniform = -std::log(static_cast<double>(options_.particles));
  particles_.assign(static_cast<std::size_t>(options_.particles),
                    Particle{Pose2{}, uniform, 0.0, map, node});
  initialized_ = true;
  best_ = 0;
  update_odometry_ = odometry;
  resetTracking(odometry);
  update_stamp_s_ = stamp_s;
  travelled_since_update_ = 0.0;
  turned_since_update_ = 0.0;
  submap_scans_ = 1;
  ++stats_.updates;
}

std::size_t Rbpf::updateParticles(const tessera::scan_matching::ScanPoints& points,
                                  const tessera::scan_matching::ScanPoints& coarse_points,
                                  const Pose2& odom_delta) {
  const Eigen::Matrix3d local_cov = motionCovariance(odom_delta);
  const double divisor = options_.weight_divisor > 0 ? options_.weight_divisor
                                                     : static_cast<double>(particles_.size());
  const std::size_t n = particles_.size();
  // Copies of one parent (after resampling, or all particles at the start) have the same pose
  // and share its map, so their matches and proposal fits are the same: each group's is found
  // once, by its first member, and only the draws differ. Outputs equal a pass per particle.
  const std::vector<std::size_t> source = copySources();
  std::vector<std::size_t> sources;
  for (std::size_t i = 0; i < n; ++i)
    if (source[i] == i) sources.push_back(i);
  struct Proposal {
    Pose2 prior;  // the motion model's mean and covariance (map frame)
    Eigen::Matrix3d prior_cov;
    Pose2 start;  // where the fine stage started: the coarse pose or the prior
    tessera::scan_matching::MatchResult match;  // the fine stage's
    bool matched = false;                       // trusted: `fit` is the proposal
    bool weak = false;      // matched, but too little of the scan on the map to trust
    bool searched = false;  // the prior's support was searched (searchPrior)
    tessera::scan_matching::ProposalFit fit;  // when matched
  };
  std::vector<Proposal> proposals(n);
  std::atomic<std::uint64_t> failures{0}, coarse_evals{0}, fine_evals{0}, recoveries{0};
  // Too little overlap with the map to trust (RbpfOptions::min_overlap_fraction).
  const auto overlaps = [&](const tessera::scan_matching::MatchResult& m) {
    return static_cast<double>(m.matched_beams) >=
           options_.min_overlap_fraction * static_cast<double>(points.size());
  };
  // The prior mean lies outside the matcher's basin (odometry off by more than the coarse kernel
  // reaches, typically a heading error after turning on the spot). Drawing from the motion model
  // instead would insert this scan at a random pose and corrupt the map, so search the prior's
  // support first: headings recovery_angular_step apart, each also shifted along x and y; the
  // best coarse score goes on to the fine stage. Its match replaces the proposal's when there
  // was none, or when it has more beams on the map than a weak one; returns whether it did.
  const auto searchPrior = [&](const Particle& p, Proposal& out, bool had_match) {
    const tessera::scan_matching::ScanMatcher& coarse_stage =
        coarse_matcher_ ? *coarse_matcher_ : matcher_;
    const tessera::scan_matching::ScanPoints& coarse_pts = coarse_matcher_ ? coarse_points : points;
    const Pose2& prior = out.prior;
    out.searched = true;
    const Eigen::Vector3d reach = options_.recovery_sigma * out.prior_cov.diagonal().cwiseSqrt();
    const int nt =
        std::min(static_cast<int>(reach.z() / options_.recovery_angular_step), kMaxRecoverySteps);
    const double lx = 0.5 * reach.x(), ly = 0.5 * reach.y();
    const Pose2 shifts[5] = {{0, 0, 0}, {lx, 0, 0}, {-lx, 0, 0}, {0, ly, 0}, {0, -ly, 0}};
    double best_score = -1.0;
    Pose2 best_pose = prior;
    std::uint64_t evals = 0;
    for (int k = -nt; k <= nt; ++k)
      for (const Pose2& d : shifts) {
        if (k == 0 && d.x == 0 && d.y == 0) continue;  // the prior mean: tried already
        const Pose2 from{prior.x + d.x, prior.y + d.y,
                         prior.theta + k * options_.recovery_angular_step};
        const tessera::scan_matching::MatchResult c = coarse_stage.match(*p.map, coarse_pts, from);
        evals += static_cast<std::uint64_t>(c.evaluations);
        if (c.success && c.score > best_score) {
          best_score = c.score;
          best_pose = c.pose;
        }
      }
    coarse_evals.fetch_add(evals, std::memory_order_relaxed);
    if (best_score < 0) return false;
    tessera::scan_matching::MatchResult recovered = matcher_.match(*p.map, points, best_pose);
    fine_evals.fetch_add(static_cast<std::uint64_t>(recovered.evaluations),
                         std::memory_order_relaxed);
    if (had_match && recovered.matched_beams <= out.match.matched_beams) return false;
    recoveries.fetch_add(1, std::memory_order_relaxed);
    out.start = best_pose;
    out.match = recovered;
    return true;
  };
  const auto finish = [&](const Particle& p, Proposal& out, bool matched) {
    // The fine stage refines the coarse pose; when it cannot (too few beams within its narrow
    // kernel), the coarse pose is still better than the odometry prior.
    const Pose2 mode = out.match.success ? out.match.pose : out.start;
    out.weak = matched && !overlaps(out.match);
    out.matched = matched && !out.weak;
    if (out.matched) out.fit = matcher_.fitProposal(*p.map, points, mode, out.prior, out.prior_cov);
  };
  const auto propose = [&](std::size_t k) {
    const std::size_t i = sources[k];
    const Particle& p = particles_[i];
    Proposal& out = proposals[i];
    out.prior = p.pose * odom_delta;
    // The odometry noise is stated in the robot frame at the previous pose.
    out.prior_cov = inMapFrame(local_cov, p.pose);
    out.start = out.prior;
    bool matched = false;
    if (coarse_matcher_) {
      const tessera::scan_matching::MatchResult coarse =
          coarse_matcher_->match(*p.map, coarse_points, out.prior);
      coarse_evals.fetch_add(static_cast<std::uint64_t>(coarse.evaluations),
                             std::memory_order_relaxed);
      if (coarse.success) out.start = coarse.pose;
      matched = coarse.success;
    }
    out.match = matcher_.match(*p.map, points, out.start);
    fine_evals.fetch_add(static_cast<std::uint64_t>(out.match.evaluations),
                         std::memory_order_relaxed);
    matched = matched || out.match.success;
    if (!matched && options_.recovery_sigma > 0) matched = searchPrior(p, out, false);
    finish(p, out, matched);
  };
  const auto draw = [&](std::size_t i) {
    Particle& p = particles_[i];
    const Proposal& proposal = proposals[source[i]];
    std::mt19937_64 rng = streamFor(options_.seed, update_index_, i);
    double log_eta = 0.0;
    if (proposal.matched) {
      const tessera::scan_matching::ProposalFit& fit = proposal.fit;
      p.pose = options_.sample_proposal ? sampleGaussian(fit.mean, fit.covariance, rng) : fit.mean;
      log_eta = fit.log_eta;
    } else {
      failures.fetch_add(1, std::memory_order_relaxed);
      p.pose = sampleGaussian(proposal.prior, proposal.prior_cov, rng);
      // The weight judges the pose drawn, not the mode the match was not trusted to find:
      // otherwise the draw that wins the weights is a random one.
      log_eta =
          matcher_.fitProposal(*p.map, points, p.pose, proposal.prior, proposal.prior_cov).log_eta;
    }
    const double inc = (std::isfinite(log_eta) ? log_eta : -1e6) / divisor;
    p.log_weight += inc;
    p.log_score += inc;
  };
  // Every proposal is found before any particle moves: copies read their source's pose.
  const auto each = [&](std::size_t count, const auto& f) {
    if (options_.parallel) {
      tbb::parallel_for(std::size_t{0}, count, f);
    } else {
      for (std::size_t k = 0; k < count; ++k) f(k);
    }
  };
  each(sources.size(), propose);
  // Weak matches get the search only when no particle has a trusted one: then the filter has
  // lost the map (as at t = 911 s of the Intel log, where the coarse stage, with its wide
  // kernel, still succeeded from every prior but left the fine stage 9-18 of 171 beams, while
  // the scan lay 0.2 m and 0.18 rad away with 120 of them on walls). While some particle holds
  // the map, the weak ones are off its mode and should lose the weights, not be moved. A weak
  // match the search itself found would only be found again.
  if (options_.recovery_sigma > 0 &&
      std::none_of(sources.begin(), sources.end(),
                   [&](std::size_t i) { return proposals[i].matched; })) {
    std::vector<std::size_t> weak;
    for (std::size_t i : sources)
      if (proposals[i].weak && !proposals[i].searched) weak.push_back(i);
    each(weak.size(), [&](std::size_t w) {
      const std::size_t i = weak[w];
      if (searchPrior(particles_[i], proposals[i], true)) finish(particles_[i], proposals[i], true);
    });
  }
  each(n, draw);
  int best_beams = 0;
  for (std::size_t i : sources) best_beams = std::max(best_beams, proposals[i].match.matched_beams);
  last_match_fraction_ = best_beams / static_cast<double>(std::max<std::size_t>(points.size(), 1));
  stats_.particle_updates += n;
  stats_.match_failures += failures.load();
  stats_.coarse_evaluations += coarse_evals.load();
  stats_.fine_evaluations += fine_evals.load();
  stats_.match_recoveries += recoveries.load();
  return failures.load();
}

double Rbpf::normalizeWeights() {
  double max_lw = -std::numeric_limits<double>::infinity();
  for (const auto& p : particles_) max_lw = std::max(max_lw, p.log_weight);
  double sum = 0.0;
  for (const auto& p : particles_) sum += std::exp(p.log_weight - max_lw);
  const double log_norm = max_lw + std::log(sum);
  double sum_sq = 0.0;
  for (auto& p : particles_) {
    p.log_weight -= log_norm;
    const double w = std::exp(p.log_weight);
    sum_sq += w * w;
  }
  return sum_sq > 0 ? 1.0 / sum_sq : 0.0;
}

void Rbpf::resample() {
  const std::size_t n = particles_.size();
  std::mt19937_64 rng = streamFor(options_.seed, update_index_, n);
  const double u0 = std::uniform_real_distribution<double>(0.0, 1.0 / static_cast<double>(n))(rng);
  const std::vector<std::size_t> drawn = systematicResample(weights(), u0);
  std::vector<Particle> next;
  next.reserve(n);
  for (std::size_t i : drawn) next.push_back(particles_[i]);  // shares map and trajectory
  const double uniform = -std::log(static_cast<double>(n));
  for (auto& p : next) p.log_weight = uniform;
  particles_ = std::move(next);
}

std::vector<std::size_t> Rbpf::copySources() const {
  const std::size_t n = particles_.size();
  std::vector<std::size_t> source(n);
  for (std::size_t i = 0; i < n; ++i) {
    source[i] = i;
    const Particle& b = particles_[i];
    for (std::size_t s = 0; s < i; ++s) {
      const Particle& a = particles_[s];
      if (source[s] == s && a.map == b.map && a.pose.x == b.pose.x && a.pose.y == b.pose.y &&
          a.pose.theta == b.pose.theta) {
        source[i] = s;
        break;
      }
    }
  }
  return source;
}

void Rbpf::insertScan(const tessera::grid::RangeScan& scan, const Pose2& mount) {
  // Particles that hold the same map at the same pose (copies from resampling) insert once and
  // keep sharing; a map also held at another pose is copied first (tiles shared, copy on write).
  struct Group {
    std::shared_ptr<tessera::grid::TiledGrid> map;
    Pose2 pose;
    std::vector<std::size_t> members;
  };
  std::vector<Group> groups;
  std::map<const tessera::grid::TiledGrid*, int> groups_per_map;
  const std::vector<std::size_t> source = copySources();
  std::vector<std::size_t> group_of(particles_.size());
  for (std::size_t i = 0; i < particles_.size(); ++i) {
    const Particle& p = particles_[i];
    if (source[i] == i) {
      group_of[i] = groups.size();
      groups.push_back({p.map, p.pose, {i}});
      ++groups_per_map[p.map.get()];
    } else {
      group_of[i] = group_of[source[i]];
      groups[group_of[i]].members.push_back(i);
    }
  }
  for (auto& g : groups) {
    // The first group of a map keeps it when no other group needs it unchanged.
    int& holders = groups_per_map[g.map.get()];
    if (holders > 1) {
      g.map = std::make_shared<tessera::grid::TiledGrid>(*g.map);
      --holders;
    }
  }
  const auto insert = [&](std::size_t k) {
    Group& g = groups[k];
    g.map->insertScan(scan, g.pose * mount, options_.insert);
  };
  if (options_.parallel) {
    tbb::parallel_for(std::size_t{0}, groups.size(), insert);
  } else {
    for (std::size_t k = 0; k < groups.size(); ++k) insert(k);
  }
  for (auto& g : groups)
    for (std::size_t i : g.members) particles_[i].map = g.map;
  ++submap_scans_;
}

int Rbpf::bestIndex() const {
  const std::size_t n = particles_.size();
  std::vector<Pose2> poses(n);
  std::vector<double> w(n), scores(n);
  for (std::size_t i = 0; i < n; ++i) {
    poses[i] = particles_[i].pose;
    w[i] = std::exp(particles_[i].log_weight);  // normalised by the update
    scores[i] = particles_[i].log_score;
  }
  return static_cast<int>(selectBestParticle(poses, w, scores, options_.best_support_linear,
                                             options_.best_support_angular));
}

void Rbpf::trackScan(const tessera::grid::RangeScan& scan, const Pose2& mount,
                     const tessera::scan_matching::ScanPoints& points, const Pose2& odometry) {
  const Pose2 moved = tessera::between(tracked_odometry_, odometry);
  const Pose2 predicted = tracked_ * moved;
  const tessera::scan_matching::ScanPoints beams =
      coarse_matcher_ ? coarse_matcher_->prepare(scan, mount) : points;
  const tessera::grid::TiledGrid& map = bestMap();
  const tessera::scan_matching::MatchResult m = tracking_matcher_.match(map, beams, predicted);
  ++stats_.tracked_scans;
  stats_.tracking_evaluations += static_cast<std::uint64_t>(m.evaluations);
  // The match is taken only when it beats the prediction in likelihood × motion prior: along a
  // corridor, or where the scan sees past the map, hill climbing on the score alone slides the
  // pose back onto mapped ground, scan after scan, since no update re-anchors it.
  bool better = false;
  if (m.success) {
    const Eigen::Matrix3d cov = inMapFrame(motionCovariance(moved), tracked_);
    const Eigen::Vector3d d(m.pose.x - predicted.x, m.pose.y - predicted.y,
                            tessera::angleDiff(m.pose.theta, predicted.theta));
    const double log_prior = -0.5 * d.dot(cov.ldlt().solve(d));
    // On every beam: the subset is enough to find the match, not to judge it.
    better = matcher_.logLikelihood(map, points, m.pose) + log_prior >
             matcher_.logLikelihood(map, points, predicted);
  }
  if (!better) ++stats_.tracking_failures;
  tracked_ = better ? m.pose : predicted;
  tracked_odometry_ = odometry;
}

void Rbpf::resetTracking(const Pose2& odometry) {
  tracked_ = particles_[static_cast<std::size_t>(best_)].pose;
  if (options_.online_mean_linear > 0 && options_.online_mean_angular > 0)
    tracked_ = kernelMean(particlePoses(), weights(), tracked_, options_.online_mean_linear,
                          options_.online_mean_angular);
  tracked_odometry_ = odometry;
}

Pose2 Rbpf::pose() const {
  if (!initialized_) return {};
  return tracked_ * tessera::between(tracked_odometry_, last_odometry_);
}

PoseWithCovariance Rbpf::poseWithCovariance() const {
  PoseWithCovariance out;
  if (!initialized_) return out;
  out.pose = particles_[static_cast<std::size_t>(best_)].pose;
  for (const auto& p : particles_) {
    const double w = std::exp(p.log_weight);
    const Eigen::Vector3d d(p.pose.x - out.pose.x, p.pose.y - out.pose.y,
                            tessera::angleDiff(p.pose.theta, out.pose.theta));
    out.covariance += w * d * d.transpose();
  }
  return out;
}

FinishedSubmap Rbpf::currentSubmap() const {
  if (!initialized_) throw std::logic_error("rbpf: no submap before the first usable scan");
  FinishedSubmap done;
  done.id = submap_id_;
  done.grid = *particles_[static_cast<std::size_t>(best_)].map;  // shares tiles
  const Pose2 since_update = tessera::between(update_odometry_, last_odometry_);
  done.next_in_this = poseWithCovariance();
  done.next_in_this.pose = pose();
  // Odometry since the last update adds its own uncertainty to the particle spread.
  done.next_in_this.covariance +=
      inMapFrame(motionCovariance(since_update), particles_[static_cast<std::size_t>(best_)].pose);
  const double lin = options_.handover_sigma_linear, ang = options_.handover_sigma_angular;
  done.next_in_this.covariance.diagonal() +=
      submap_travelled_ * Eigen::Vector3d(lin * lin, lin * lin, ang * ang);
  done.scans_inserted = submap_scans_;
  done.travelled_m = submap_travelled_;
  return done;
}

FinishedSubmap Rbpf::startSubmapLost() {
  if (!initialized_) throw std::logic_error("rbpf: no submap before the first usable scan");
  kept_.clear();  // views of the place the robot was taken from
  FinishedSubmap done = startSubmap();
  const double lin = options_.lost_sigma_linear, ang = options_.lost_sigma_angular;
  done.next_in_this.covariance = Eigen::Vector3d(lin * lin, lin * lin, ang * ang).asDiagonal();
  return done;
}

FinishedSubmap Rbpf::startSubmap() {
  noteMapBytes();  // the submap's maps at their largest, before they go
  FinishedSubmap done = currentSubmap();
  suspect_run_ = 0;
  ++submap_id_;
  submap_scans_ = 0;
  submap_travelled_ = 0.0;
  auto map = std::make_shared<tessera::grid::TiledGrid>(options_.grid);
  // The last metres' update scans at the best particle's poses, seen from the new origin.
  const Pose2 to_new = done.next_in_this.pose.inverse();
  const TrajectoryNode* node_at = particles_[static_cast<std::size_t>(best_)].node.get();
  for (auto k = kept_.rbegin(); k != kept_.rend(); ++k) {
    while (node_at && node_at->stamp_s > k->stamp_s) node_at = node_at->parent.get();
    if (!node_at) break;
    if (node_at->stamp_s != k->stamp_s || k->stamp_s == last_stamp_s_) continue;
    map->insertScan(k->scan, to_new * node_at->pose * k->mount, options_.insert);
    ++submap_scans_;
  }
  kept_.clear();
  if (last_scan_usable_) {
    map->insertScan(last_scan_, last_mount_, options_.insert);
    ++submap_scans_;
  }
  auto node =
      std::make_shared<const TrajectoryNode>(TrajectoryNode{last_stamp_s_, Pose2{}, nullptr});
  const double uniform = -std::log(static_cast<double>(particles_.size()));
  for (auto& p : particles_) p = Particle{Pose2{}, uniform, 0.0, map, node};
  best_ = 0;
  update_odometry_ = last_odometry_;
  resetTracking(last_odometry_);
  update_stamp_s_ = last_stamp_s_;
  travelled_since_update_ = 0.0;
  turned_since_update_ = 0.0;
  return done;
}

const tessera::grid::TiledGrid& Rbpf::bestMap() const {
  if (!initialized_) throw std::logic_error("rbpf: no map before the first usable scan");
  return *particles_[static_cast<std::size_t>(best_)].map;
}

std::vector<Rbpf::StampedPose> Rbpf::bestTrajectory() const {
  std::vector<StampedPose> out;
  if (!initialized_) return out;
  for (auto n = particles_[static_cast<std::size_t>(best_)].node; n; n = n->parent)
    out.push_back({n->stamp_s, n->pose});
  std::reverse(out.begin(), out.end());
  return out;
}

std::vector<Pose2> Rbpf::particlePoses() const {
  std::vector<Pose2> out;
  out.reserve(particles_.size());
  for (const auto& p : particles_) out.push_back(p.pose);
  return out;
}

std::vector<double> Rbpf::weights() const {
  std::vector<double> w;
  w.reserve(particles_.size());
  for (const auto& p : particles_) w.push_back(std::exp(p.log_weight));
  return w;
}

namespace {

/// The particles' map objects, each once (copies made by resampling share one).
template <class Particles>
std::vector<const tessera::grid::TiledGrid*> distinctMapsOf(const Particles& particles) {
  std::vector<const tessera::grid::TiledGrid*> maps;
  for (const auto& p : particles) maps.push_back(p.map.get());
  std::sort(maps.begin(), maps.end());
  maps.erase(std::unique(maps.begin(), maps.end()), maps.end());
  return maps;
}

}  // namespace

int Rbpf::distinctMaps() const {
  return static_cast<int>(distinctMapsOf(particles_).size());
}

void Rbpf::noteMapBytes() {
  stats_.map_bytes_peak = std::max(stats_.map_bytes_peak, mapBytes());
}

std::size_t Rbpf::mapBytes() const {
  double bytes = 0.0;
  for (const auto* map : distinctMapsOf(particles_)) bytes += map->sharedMemoryBytes();
  return static_cast<std::size_t>(std::llround(bytes));
}

}  // namespace tessera::laser_slam
