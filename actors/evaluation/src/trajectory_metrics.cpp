#include <tessera/evaluation/trajectory_metrics.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>
#include <sstream>
#include <string>
#include <tuple>
#include <unordered_map>

namespace tessera::evaluation {
namespace {

constexpr double kRadToDeg = 180.0 / std::numbers::pi;

std::int64_t secondsToNs(double s) {
  // Beyond ±292 years int64 ns overflow; such spans mean "no limit" for every caller here.
  if (!std::isfinite(s) || std::abs(s) > 9.2e9)
    return s < 0 ? std::numeric_limits<std::int64_t>::min() / 2
                 : std::numeric_limits<std::int64_t>::max() / 2;
  return std::llround(s * 1e9);
}

/// Indices of `poses` in stamp order (stable: equal stamps keep file order).
std::vector<std::size_t> stampOrder(const std::vector<mapping::TumPose>& poses) {
  std::vector<std::size_t> order(poses.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return poses[a].stamp_ns < poses[b].stamp_ns;
  });
  return order;
}

Eigen::Isometry3d isometry(const mapping::TumPose& p) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = p.orientation.normalized().toRotationMatrix();
  t.translation() = p.position;
  return t;
}

bool planarMode(Dimension d, const std::vector<mapping::TumPose>& a,
                const std::vector<mapping::TumPose>& b) {
  if (d == Dimension::kPlanar) return true;
  if (d == Dimension::kSpatial) return false;
  return isPlanar(a) && isPlanar(b);
}

}  // namespace

ErrorStats summarize(std::vector<double> values) {
  ErrorStats s;
  s.count = values.size();
  if (values.empty()) return s;
  const double n = static_cast<double>(values.size());
  double sum = 0, sum_sq = 0;
  for (double v : values) {
    sum += v;
    sum_sq += v * v;
  }
  s.mean = sum / n;
  s.rmse = std::sqrt(sum_sq / n);
  if (values.size() > 1) {
    // Two-pass variance: the one-pass formula loses digits when the mean dominates.
    double ss = 0;
    for (double v : values) ss += (v - s.mean) * (v - s.mean);
    s.std = std::sqrt(ss / (n - 1));
  }
  std::sort(values.begin(), values.end());
  s.min = values.front();
  s.max = values.back();
  const std::size_t mid = values.size() / 2;
  s.median = values.size() % 2 == 1 ? values[mid] : 0.5 * (values[mid - 1] + values[mid]);
  return s;
}

bool isPlanar(const std::vector<mapping::TumPose>& poses, double tol) {
  return std::all_of(poses.begin(), poses.end(), [tol](const mapping::TumPose& p) {
    return std::abs(p.position.z()) <= tol && std::abs(p.orientation.x()) <= tol &&
           std::abs(p.orientation.y()) <= tol;
  });
}

Alignment alignPoints(const Eigen::Matrix3Xd& from, const Eigen::Matrix3Xd& to, bool planar,
                      bool with_scale) {
  if (from.cols() != to.cols())
    throw MetricError("alignPoints: " + std::to_string(from.cols()) + " points to align onto " +
                      std::to_string(to.cols()));
  if (from.cols() == 0) throw MetricError("alignment needs at least one point pair");
  const int rows = planar ? 2 : 3;
  Alignment a;
  if (from.cols() == 1) {
    a.translation.head(rows) = to.col(0).head(rows) - from.col(0).head(rows);
    return a;
  }
  const Eigen::MatrixXd f = from.topRows(rows);
  const Eigen::MatrixXd t = to.topRows(rows);
  if (with_scale) {
    const double spread = (f.colwise() - f.rowwise().mean()).squaredNorm();
    if (!(spread > 1e-18))
      throw MetricError("cannot estimate a scale: the estimate points all coincide");
  }
  const Eigen::MatrixXd m = Eigen::umeyama(f, t, with_scale);
  const Eigen::MatrixXd sr = m.topLeftCorner(rows, rows);
  a.scale = with_scale ? sr.col(0).norm() : 1.0;
  a.rotation.topLeftCorner(rows, rows) = sr / a.scale;
  a.translation.head(rows) = m.topRightCorner(rows, 1);
  return a;
}

std::vector<std::pair<std::size_t, std::size_t>> associateByTime(
    const std::vector<mapping::TumPose>& estimate, const std::vector<mapping::TumPose>& reference,
    const AssociationOptions& options) {
  const std::int64_t max_diff = secondsToNs(options.max_difference_s);
  const std::int64_t offset = secondsToNs(options.offset_s);
  if (max_diff < 0) throw MetricError("association: max difference must not be negative");

  const std::vector<std::size_t> ref_order = stampOrder(reference);
  std::vector<std::int64_t> ref_stamps;
  ref_stamps.reserve(reference.size());
  for (std::size_t k : ref_order) ref_stamps.push_back(reference[k].stamp_ns);

  // Candidates closest first, each pose used once (the greedy rule of TUM's associate.py).
  // Only the few nearest reference stamps of each estimate pose can win, so a generous
  // max_difference does not make this quadratic.
  constexpr std::size_t kNearest = 16;
  std::vector<std::tuple<std::int64_t, std::size_t, std::size_t>> candidates;
  for (std::size_t i = 0; i < estimate.size(); ++i) {
    const std::int64_t t = estimate[i].stamp_ns + offset;
    std::size_t lo = static_cast<std::size_t>(
        std::lower_bound(ref_stamps.begin(), ref_stamps.end(), t) - ref_stamps.begin());
    std::size_t hi = lo;  // candidates are [lo, hi) grown outwards from t
    for (std::size_t taken = 0; taken < kNearest; ++taken) {
      const bool can_lo = lo > 0, can_hi = hi < ref_stamps.size();
      if (!can_lo && !can_hi) break;
      std::size_t k;
      if (can_hi && (!can_lo || ref_stamps[hi] - t <= t - ref_stamps[lo - 1]))
        k = hi++;
      else
        k = --lo;
      const std::int64_t d = ref_stamps[k] > t ? ref_stamps[k] - t : t - ref_stamps[k];
      if (d > max_diff) break;  // the next one is further still
      candidates.emplace_back(d, i, ref_order[k]);
    }
  }
  std::sort(candidates.begin(), candidates.end());
  std::vector<char> est_used(estimate.size(), 0), ref_used(reference.size(), 0);
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (const auto& [d, i, j] : candidates) {
    if (est_used[i] || ref_used[j]) continue;
    est_used[i] = ref_used[j] = 1;
    pairs.emplace_back(i, j);
  }
  std::sort(pairs.begin(), pairs.end(), [&](const auto& a, const auto& b) {
    return std::make_pair(estimate[a.first].stamp_ns, a.first) <
           std::make_pair(estimate[b.first].stamp_ns, b.first);
  });
  return pairs;
}

AteResult computeAte(const std::vector<mapping::TumPose>& estimate,
                     const std::vector<mapping::TumPose>& reference, const AteOptions& options) {
  AteResult r;
  r.estimate_poses = estimate.size();
  r.reference_poses = reference.size();
  r.planar = planarMode(options.dimension, estimate, reference);
  const auto pairs = associateByTime(estimate, reference, options.association);
  r.pairs = pairs.size();
  if (pairs.empty())
    throw MetricError("ATE: no estimate/reference stamps within " +
                      std::to_string(options.association.max_difference_s) +
                      " s of each other (check the time bases, or --max-diff / --offset)");
  Eigen::Matrix3Xd from(3, pairs.size()), to(3, pairs.size());
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    from.col(static_cast<Eigen::Index>(k)) = estimate[pairs[k].first].position;
    to.col(static_cast<Eigen::Index>(k)) = reference[pairs[k].second].position;
  }
  r.alignment = alignPoints(from, to, r.planar, options.scale);
  r.errors.reserve(pairs.size());
  for (Eigen::Index k = 0; k < from.cols(); ++k) {
    const Eigen::Vector3d d = r.alignment.apply(from.col(k)) - to.col(k);
    r.errors.push_back(r.planar ? d.head<2>().norm() : d.norm());
  }
  r.translation = summarize(r.errors);
  return r;
}

JointAteResult computeJointAte(
    const std::vector<std::pair<std::vector<mapping::TumPose>, std::vector<mapping::TumPose>>>&
        trajectories,
    const AteOptions& options) {
  if (trajectories.empty()) throw MetricError("joint ATE: no trajectories");
  if (options.scale) throw MetricError("joint ATE: scale alignment is not supported");
  JointAteResult r;
  std::vector<Eigen::Vector3d> from, to;
  std::vector<std::size_t> owner;
  r.planar = true;
  for (const auto& [estimate, reference] : trajectories)
    r.planar = r.planar && planarMode(options.dimension, estimate, reference);
  AteOptions alone = options;
  alone.dimension = r.planar ? Dimension::kPlanar : Dimension::kSpatial;
  for (std::size_t t = 0; t < trajectories.size(); ++t) {
    const auto& [estimate, reference] = trajectories[t];
    try {
      r.alone.push_back(computeAte(estimate, reference, alone));
    } catch (const MetricError& e) {
      throw MetricError("trajectory " + std::to_string(t + 1) + ": " + e.what());
    }
    for (const auto& [e, f] : associateByTime(estimate, reference, options.association)) {
      from.push_back(estimate[e].position);
      to.push_back(reference[f].position);
      owner.push_back(t);
    }
  }
  Eigen::Matrix3Xd a(3, static_cast<Eigen::Index>(from.size())),
      b(3, static_cast<Eigen::Index>(to.size()));
  for (std::size_t k = 0; k < from.size(); ++k) {
    a.col(static_cast<Eigen::Index>(k)) = from[k];
    b.col(static_cast<Eigen::Index>(k)) = to[k];
  }
  r.alignment = alignPoints(a, b, r.planar, false);
  std::vector<std::vector<double>> errors(trajectories.size());
  for (std::size_t k = 0; k < from.size(); ++k) {
    const Eigen::Vector3d d = r.alignment.apply(from[k]) - to[k];
    errors[owner[k]].push_back(r.planar ? d.head<2>().norm() : d.norm());
  }
  for (auto& e : errors) r.joint.push_back(summarize(std::move(e)));
  return r;
}

HeadingDriftResult computeHeadingDrift(const std::vector<mapping::TumPose>& estimate,
                                       const std::vector<mapping::TumPose>& reference,
                                       const AssociationOptions& options) {
  HeadingDriftResult r;
  r.estimate_poses = estimate.size();
  r.reference_poses = reference.size();
  const auto pairs = associateByTime(estimate, reference, options);
  r.pairs = pairs.size();
  if (pairs.empty())
    throw MetricError("heading drift: no estimate/reference stamps within " +
                      std::to_string(options.max_difference_s) +
                      " s of each other (check the time bases, or --max-diff / --offset)");
  std::vector<double> errors;
  errors.reserve(pairs.size());
  double e = 0;  // unwrapped [rad]
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    if (k > 0) {
      const double de = normalizeAngle(estimate[pairs[k].first].planar().theta -
                                       estimate[pairs[k - 1].first].planar().theta);
      const double dr = normalizeAngle(reference[pairs[k].second].planar().theta -
                                       reference[pairs[k - 1].second].planar().theta);
      e += normalizeAngle(de - dr);
    }
    errors.push_back(std::abs(e) * 180.0 / std::numbers::pi);
  }
  r.final_signed_deg = e * 180.0 / std::numbers::pi;
  r.final_deg = errors.back();
  r.duration_s = static_cast<double>(reference[pairs.back().second].stamp_ns -
                                     reference[pairs.front().second].stamp_ns) *
                 1e-9;
  r.error_deg = summarize(std::move(errors));
  return r;
}

RpeResult computeRpe(const std::vector<mapping::TumPose>& estimate,
                     const std::vector<mapping::TumPose>& reference, const RpeOptions& options) {
  RpeResult r;
  r.estimate_poses = estimate.size();
  r.reference_poses = reference.size();
  r.planar = planarMode(options.dimension, estimate, reference);
  if (!(options.delta > 0) || !std::isfinite(options.delta))
    throw MetricError("RPE: delta must be positive");
  if (options.unit == DeltaUnit::kFrames && options.delta != std::floor(options.delta))
    throw MetricError("RPE: a delta in frames must be a whole number");
  if (reference.size() < 2) throw MetricError("RPE: the reference needs at least two poses");

  const std::vector<std::size_t> est_order = stampOrder(estimate);
  const std::vector<std::size_t> ref_order = stampOrder(reference);
  std::vector<std::int64_t> est_stamps, ref_stamps, ref_intervals;
  for (std::size_t k : est_order) est_stamps.push_back(estimate[k].stamp_ns);
  for (std::size_t k : ref_order) ref_stamps.push_back(reference[k].stamp_ns);
  for (std::size_t k = 1; k < ref_stamps.size(); ++k)
    ref_intervals.push_back(ref_stamps[k] - ref_stamps[k - 1]);
  std::nth_element(ref_intervals.begin(), ref_intervals.begin() + ref_intervals.size() / 2,
                   ref_intervals.end());
  // TUM's rule: a reference pose more than two reference periods away is not "the same time".
  const std::int64_t max_ref_diff = 2 * ref_intervals[ref_intervals.size() / 2];
  const std::int64_t offset = secondsToNs(options.offset_s);

  // The reference pose for estimate stamp t, or nullptr.
  auto referenceAt = [&](std::int64_t t) -> const mapping::TumPose* {
    const std::size_t k = nearestIndex(ref_stamps, t + offset);
    const std::int64_t d = ref_stamps[k] - (t + offset);
    return std::abs(d) <= max_ref_diff ? &reference[ref_order[k]] : nullptr;
  };

  std::vector<double> trans, rot;
  const std::size_t n = est_stamps.size();
  const std::int64_t delta_ns = secondsToNs(options.delta);
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t j;
    if (options.unit == DeltaUnit::kFrames) {
      const double jd = static_cast<double>(i) + options.delta;
      if (jd >= static_cast<double>(n)) break;
      j = static_cast<std::size_t>(jd);
    } else {
      const std::int64_t target = est_stamps[i] + delta_ns;
      if (target > est_stamps.back()) break;  // the rest would pair with the last pose
      j = nearestIndex(est_stamps, target);
      if (j <= i) continue;
    }
    const mapping::TumPose* g0 = referenceAt(est_stamps[i]);
    const mapping::TumPose* g1 = referenceAt(est_stamps[j]);
    if (!g0 || !g1) continue;
    const mapping::TumPose& p0 = estimate[est_order[i]];
    const mapping::TumPose& p1 = estimate[est_order[j]];
    if (r.planar) {
      const Pose2 e =
          between(between(g0->planar(), g1->planar()), between(p0.planar(), p1.planar()));
      trans.push_back(std::hypot(e.x, e.y));
      rot.push_back(std::abs(e.theta) * kRadToDeg);
    } else {
      const Eigen::Isometry3d e = (isometry(*g0).inverse() * isometry(*g1)).inverse() *
                                  (isometry(p0).inverse() * isometry(p1));
      trans.push_back(e.translation().norm());
      rot.push_back(std::abs(Eigen::AngleAxisd(e.rotation()).angle()) * kRadToDeg);
    }
  }
  r.pairs = trans.size();
  if (trans.empty())
    throw MetricError("RPE: no pose pairs " + std::to_string(options.delta) +
                      (options.unit == DeltaUnit::kFrames ? " frames" : " s") +
                      " apart have reference poses (check the time bases or --delta)");
  r.translation = summarize(std::move(trans));
  r.rotation_deg = summarize(std::move(rot));
  return r;
}

PlanarTrajectory::PlanarTrajectory(const std::vector<mapping::TumPose>& poses) {
  for (std::size_t k : stampOrder(poses)) {
    stamps_.push_back(poses[k].stamp_ns);
    poses_.push_back(poses[k].planar());
  }
}

PlanarTrajectory::Lookup PlanarTrajectory::at(std::int64_t t, std::int64_t max_gap_ns,
                                              Pose2& pose) const {
  if (stamps_.empty() || t < stamps_.front() || t > stamps_.back()) return Lookup::kOutside;
  // lo: the last pose stamped at or before t; hi: the first one after it. With repeated stamps
  // (logs whose clock stalled) this interpolates between the poses that are nearest in order.
  const auto it = std::upper_bound(stamps_.begin(), stamps_.end(), t);
  const std::size_t hi = static_cast<std::size_t>(it - stamps_.begin());
  const std::size_t lo = hi - 1;  // t ≥ front, so hi ≥ 1
  if (stamps_[lo] == t) {
    pose = poses_[lo];
    return Lookup::kOk;
  }
  const std::int64_t span = stamps_[hi] - stamps_[lo];
  if (max_gap_ns > 0 && span > max_gap_ns) return Lookup::kInGap;
  const double w = static_cast<double>(t - stamps_[lo]) / static_cast<double>(span);
  pose = interpolate(poses_[lo], poses_[hi], w);
  return Lookup::kOk;
}

RelationsResult computeRelationsError(const std::vector<mapping::TumPose>& trajectory,
                                      const std::vector<PoseRelation>& relations,
                                      const RelationsOptions& options) {
  if (!(options.max_speed >= 0))
    throw MetricError("relations: max_speed must be a number >= 0 (0: off)");
  const PlanarTrajectory traj(trajectory);
  const std::int64_t offset = secondsToNs(options.time_offset_s);
  const std::int64_t max_gap = options.max_gap_s > 0 ? secondsToNs(options.max_gap_s) : 0;
  RelationsResult r;
  r.relations = relations.size();
  r.errors.reserve(relations.size());
  std::vector<double> trans, trans_sq, rot, rot_sq;
  std::vector<double> ok_trans, ok_trans_sq, ok_rot, ok_rot_sq;  // consistent with the stamps
  for (const PoseRelation& rel : relations) {
    RelationError& out = r.errors.emplace_back();
    out.t1_ns = rel.t1_ns;
    out.t2_ns = rel.t2_ns;
    const double distance = std::hypot(rel.delta.x, rel.delta.y);
    const double dt = std::abs(static_cast<double>(rel.t2_ns - rel.t1_ns)) * 1e-9;
    out.speed = distance == 0 ? 0.0
                : dt > 0      ? distance / dt
                              : std::numeric_limits<double>::infinity();
    // A NaN displacement is never "consistent": it cannot be shown to fit its stamps.
    out.consistent = options.max_speed == 0 || out.speed <= options.max_speed;

    Pose2 x1, x2;
    // Relation times are in the relations' time base; the trajectory's is offset from it.
    const auto l1 = traj.at(rel.t1_ns - offset, max_gap, x1);
    const auto l2 = traj.at(rel.t2_ns - offset, max_gap, x2);
    if (l1 == PlanarTrajectory::Lookup::kOutside || l2 == PlanarTrajectory::Lookup::kOutside) {
      ++r.outside;
      continue;
    }
    if (l1 != PlanarTrajectory::Lookup::kOk || l2 != PlanarTrajectory::Lookup::kOk) {
      ++r.in_gap;
      continue;
    }
    const Pose2 e = between(rel.delta, between(x1, x2));
    const double t = std::hypot(e.x, e.y);
    const double a = std::abs(e.theta) * kRadToDeg;
    out.matched = true;
    out.translation = t;
    out.rotation_rad = std::abs(e.theta);
    trans.push_back(t);
    trans_sq.push_back(t * t);
    rot.push_back(a);
    rot_sq.push_back(a * a);
    if (out.consistent) {
      ok_trans.push_back(t);
      ok_trans_sq.push_back(t * t);
      ok_rot.push_back(a);
      ok_rot_sq.push_back(a * a);
    } else {
      ++r.inconsistent;
    }
  }
  r.matched = trans.size();
  if (r.matched == 0)
    throw MetricError("relations: none of the " + std::to_string(r.relations) +
                      " relations falls inside the trajectory (" + std::to_string(r.outside) +
                      " outside, " + std::to_string(r.in_gap) +
                      " in gaps; check the time base or --time-offset)");
  r.translation = summarize(std::move(trans));
  r.translation_squared = summarize(std::move(trans_sq));
  r.rotation_deg = summarize(std::move(rot));
  r.rotation_squared_deg = summarize(std::move(rot_sq));
  r.consistent_translation = summarize(std::move(ok_trans));
  r.consistent_translation_squared = summarize(std::move(ok_trans_sq));
  r.consistent_rotation_deg = summarize(std::move(ok_rot));
  r.consistent_rotation_squared_deg = summarize(std::move(ok_rot_sq));
  return r;
}

std::vector<RelationsBin> binRelationErrors(const std::vector<RelationError>& errors,
                                            double width_s) {
  if (!(width_s > 0) || !std::isfinite(width_s))
    throw MetricError("relation bins: the width must be a positive number of seconds");
  std::vector<RelationsBin> bins;
  if (errors.empty()) return bins;
  const auto [first, last] = std::minmax_element(
      errors.begin(), errors.end(),
      [](const RelationError& a, const RelationError& b) { return a.t1_ns < b.t1_ns; });
  const std::int64_t t0 = first->t1_ns;
  const auto binOf = [&](std::int64_t t1_ns) {
    return std::floor(static_cast<double>(t1_ns - t0) * 1e-9 / width_s);
  };
  constexpr double kMaxBins = 1'000'000;
  const double last_bin = binOf(last->t1_ns);
  if (!(last_bin < kMaxBins)) {
    std::ostringstream message;
    message << "relation bins: " << width_s << " s bins over "
            << static_cast<double>(last->t1_ns - t0) * 1e-9
            << " s would make more than 1000000 bins";
    throw MetricError(message.str());
  }
  bins.resize(static_cast<std::size_t>(last_bin) + 1);
  std::vector<double> rot_sum(bins.size(), 0.0);
  for (std::size_t k = 0; k < bins.size(); ++k) bins[k].start_s = static_cast<double>(k) * width_s;
  for (const RelationError& e : errors) {
    if (!e.matched) continue;
    const std::size_t k = static_cast<std::size_t>(binOf(e.t1_ns));
    ++bins[k].count;
    bins[k].translation_mean += e.translation;
    rot_sum[k] += e.rotation_rad;
  }
  for (std::size_t k = 0; k < bins.size(); ++k) {
    if (bins[k].count == 0) continue;
    const double n = static_cast<double>(bins[k].count);
    bins[k].translation_mean /= n;
    bins[k].rotation_mean_deg = rot_sum[k] / n * kRadToDeg;
  }
  return bins;
}

LandmarkResult computeLandmarkError(const std::vector<Landmark>& estimate,
                                    const std::vector<Landmark>& reference, bool scale) {
  LandmarkResult r;
  r.estimate_landmarks = estimate.size();
  r.reference_landmarks = reference.size();
  std::unordered_map<std::int64_t, std::size_t> ref_index;
  for (std::size_t k = 0; k < reference.size(); ++k) ref_index.emplace(reference[k].id, k);
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (std::size_t k = 0; k < estimate.size(); ++k) {
    const auto it = ref_index.find(estimate[k].id);
    if (it != ref_index.end()) pairs.emplace_back(k, it->second);
  }
  r.pairs = pairs.size();
  if (pairs.empty())
    throw MetricError("landmarks: no id is in both the estimate and the reference");
  Eigen::Matrix3Xd from = Eigen::Matrix3Xd::Zero(3, static_cast<Eigen::Index>(pairs.size()));
  Eigen::Matrix3Xd to = from;
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    from.col(static_cast<Eigen::Index>(k)).head<2>() = estimate[pairs[k].first].position;
    to.col(static_cast<Eigen::Index>(k)).head<2>() = reference[pairs[k].second].position;
  }
  r.alignment = alignPoints(from, to, /*planar=*/true, scale);
  std::vector<double> errors;
  for (Eigen::Index k = 0; k < from.cols(); ++k)
    errors.push_back((r.alignment.apply(from.col(k)) - to.col(k)).head<2>().norm());
  r.error = summarize(std::move(errors));
  return r;
}

std::size_t nearestIndex(const std::vector<std::int64_t>& stamps, std::int64_t t) {
  const auto it = std::lower_bound(stamps.begin(), stamps.end(), t);
  if (it == stamps.begin()) return 0;
  if (it == stamps.end()) return stamps.size() - 1;
  const std::size_t hi = static_cast<std::size_t>(it - stamps.begin());
  return (*it - t) < (t - stamps[hi - 1]) ? hi : hi - 1;
}

}  // namespace tessera::evaluation
