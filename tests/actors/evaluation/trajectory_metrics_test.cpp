#include <tessera/evaluation/landmark_io.hpp>
#include <tessera/evaluation/loop_metrics.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Geometry>

#include <cmath>
#include <limits>
#include <numbers>

#include "../../shared_data.hpp"

using namespace tessera::evaluation;
using namespace tessera::mapping;
using namespace tessera;
using std::numbers::pi;

namespace {

constexpr std::int64_t kSec = 1'000'000'000;

/// A planar loop: a circle of radius 5 m driven at 0.5 rad/s, sampled at `hz`, plus a slow
/// wobble so that the trajectory is not degenerate for alignment.
std::vector<TumPose> planarLoop(double seconds, double hz, std::int64_t t0_ns = 100 * kSec) {
  std::vector<TumPose> out;
  const int n = static_cast<int>(seconds * hz);
  for (int k = 0; k <= n; ++k) {
    const double t = k / hz;
    const double a = 0.5 * t;
    const double r = 5.0 + 0.5 * std::sin(0.3 * t);
    out.push_back(TumPose::fromPlanar(t0_ns + std::llround(t * 1e9),
                                      Pose2(r * std::cos(a), r * std::sin(a), a + pi / 2)));
  }
  return out;
}

/// A 3D helix with a varying attitude.
std::vector<TumPose> helix(int n, double hz) {
  std::vector<TumPose> out;
  for (int k = 0; k < n; ++k) {
    const double t = k / hz;
    TumPose p;
    p.stamp_ns = std::llround(t * 1e9);
    p.position = {3 * std::cos(0.4 * t), 3 * std::sin(0.4 * t), 0.2 * t};
    p.orientation = Eigen::AngleAxisd(0.4 * t, Eigen::Vector3d::UnitZ()) *
                    Eigen::AngleAxisd(0.1 * std::sin(t), Eigen::Vector3d::UnitX());
    out.push_back(p);
  }
  return out;
}

/// Applies the rigid motion (R, t) to every pose: the same trajectory in another world frame.
std::vector<TumPose> transformed(std::vector<TumPose> poses, const Eigen::Quaterniond& q,
                                 const Eigen::Vector3d& t) {
  for (auto& p : poses) {
    p.position = q * p.position + t;
    p.orientation = q * p.orientation;
  }
  return poses;
}

}  // namespace

TEST_CASE("summarize gives rmse, mean, sample std, median, min and max", "[eval][metrics]") {
  const ErrorStats s = summarize({4, 1, 3, 2});
  CHECK(s.count == 4);
  CHECK(s.mean == Approx(2.5));
  CHECK(s.rmse == Approx(std::sqrt(7.5)));
  CHECK(s.std == Approx(std::sqrt(5.0 / 3.0)));
  CHECK(s.median == Approx(2.5));
  CHECK(s.min == 1);
  CHECK(s.max == 4);
  CHECK(summarize({7, 1, 3}).median == 3);
  CHECK(summarize({5}).std == 0);
  CHECK(summarize({}).count == 0);
}

TEST_CASE("planar detection looks at z and the rotation axis", "[eval][metrics]") {
  CHECK(isPlanar(planarLoop(10, 1)));
  CHECK_FALSE(isPlanar(helix(10, 1)));
  auto tilted = planarLoop(10, 1);
  tilted[3].orientation = Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()) * tilted[3].orientation;
  CHECK_FALSE(isPlanar(tilted));
}

TEST_CASE("ATE of a trajectory against itself is zero", "[eval][ate]") {
  const auto traj = planarLoop(60, 10);
  const AteResult r = computeAte(traj, traj);
  CHECK(r.pairs == traj.size());
  CHECK(r.planar);
  CHECK(r.translation.rmse < 1e-9);
  CHECK(r.translation.max < 1e-9);
}

TEST_CASE("ATE aligns away a rigid change of world frame, in 3D and in the plane", "[eval][ate]") {
  SECTION("SE(3)") {
    const auto reference = helix(200, 10);
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()));
    const auto estimate = transformed(reference, q, {4, -2, 1});
    const AteResult r = computeAte(estimate, reference);
    CHECK_FALSE(r.planar);
    CHECK(r.pairs == 200);
    CHECK(r.translation.max < 1e-9);
    // The alignment is the inverse of the change of frame.
    CHECK(r.alignment.rotation.isApprox(q.inverse().toRotationMatrix(), 1e-9));
    // Without alignment the error would be metres: check the test can fail.
    const AteResult unaligned = computeAte(transformed(reference, q, {4, -2, 1}), reference);
    CHECK(unaligned.alignment.translation.norm() > 1);
  }
  SECTION("SE(2)") {
    const auto reference = planarLoop(60, 10);
    const Eigen::Quaterniond q(Eigen::AngleAxisd(2.5, Eigen::Vector3d::UnitZ()));
    const auto estimate = transformed(reference, q, {-3, 7, 0});
    const AteResult r = computeAte(estimate, reference);
    CHECK(r.planar);
    CHECK(r.translation.max < 1e-9);
    CHECK(std::atan2(r.alignment.rotation(1, 0), r.alignment.rotation(0, 0)) ==
          Approx(-2.5).margin(1e-9));
  }
}

TEST_CASE("ATE measures a known residual error that no alignment can remove", "[eval][ate]") {
  // Four corners of a square each pushed 0.1 m outwards: by symmetry the best rigid alignment is
  // the identity and every error is 0.1 m; with scale the square shrinks back to 0 error.
  std::vector<TumPose> reference, estimate;
  const std::vector<Eigen::Vector2d> corners{{1, 1}, {-1, 1}, {-1, -1}, {1, -1}};
  for (std::size_t k = 0; k < corners.size(); ++k) {
    const Eigen::Vector2d c = corners[k];
    const Eigen::Vector2d pushed = c + 0.1 * c.normalized();
    reference.push_back(TumPose::fromPlanar(static_cast<std::int64_t>(k) * kSec, Pose2(c, 0)));
    estimate.push_back(TumPose::fromPlanar(static_cast<std::int64_t>(k) * kSec, Pose2(pushed, 0)));
  }
  const AteResult rigid = computeAte(estimate, reference);
  CHECK(rigid.translation.rmse == Approx(0.1));
  CHECK(rigid.translation.max == Approx(0.1));
  AteOptions with_scale;
  with_scale.scale = true;
  const AteResult sim = computeAte(estimate, reference, with_scale);
  CHECK(sim.translation.max < 1e-9);
  CHECK(sim.alignment.scale == Approx(std::sqrt(2.0) / (std::sqrt(2.0) + 0.1)));
}

TEST_CASE("ATE associates stamps within max difference, closest first, with an offset",
          "[eval][ate]") {
  const auto reference = planarLoop(20, 10);
  auto shifted = reference;
  for (auto& p : shifted) p.stamp_ns += 15'000'000;  // 15 ms late
  CHECK(computeAte(shifted, reference).pairs == reference.size());

  for (auto& p : shifted) p.stamp_ns += 15'000'000;  // now 30 ms: beyond the 20 ms default
  CHECK_THROWS_AS(computeAte(shifted, reference), MetricError);
  AteOptions options;
  options.association.offset_s = -0.03;
  const AteResult r = computeAte(shifted, reference, options);
  CHECK(r.pairs == reference.size());
  CHECK(r.translation.max < 1e-9);

  // Each pose is used once, and the closest candidate wins.
  std::vector<TumPose> est{TumPose::fromPlanar(1000'000'000, {}),
                           TumPose::fromPlanar(1005'000'000, {})};
  std::vector<TumPose> ref{TumPose::fromPlanar(1004'000'000, {})};
  const auto pairs = associateByTime(est, ref, {});
  REQUIRE(pairs.size() == 1);
  CHECK(pairs[0] == std::pair<std::size_t, std::size_t>{1, 0});
}

TEST_CASE("RPE of a rigidly moved copy is zero: changes of world frame do not matter",
          "[eval][rpe]") {
  const auto reference = helix(300, 10);
  const Eigen::Quaterniond q(Eigen::AngleAxisd(1.1, Eigen::Vector3d(0, 1, 1).normalized()));
  const RpeResult r = computeRpe(transformed(reference, q, {1, 2, 3}), reference);
  CHECK_FALSE(r.planar);
  CHECK(r.pairs == 290);  // 30 s of data, pairs 1 s apart
  CHECK(r.translation.max < 1e-9);
  CHECK(r.rotation_deg.max < 1e-6);
}

TEST_CASE("RPE of odometry with a known scale and heading bias", "[eval][rpe]") {
  // Reference: straight line at 1 m/s along x, 10 Hz. Estimate: 1.1 m/s (10 % too long), so
  // every 1 s pair is off by exactly 0.1 m along the motion and not at all in rotation.
  std::vector<TumPose> reference, estimate;
  for (int k = 0; k <= 100; ++k) {
    const std::int64_t t = k * kSec / 10;
    reference.push_back(TumPose::fromPlanar(t, Pose2(0.1 * k, 0, 0)));
    estimate.push_back(TumPose::fromPlanar(t, Pose2(0.11 * k, 0, 0)));
  }
  const RpeResult r = computeRpe(estimate, reference);
  CHECK(r.planar);
  CHECK(r.pairs == 91);
  CHECK(r.translation.rmse == Approx(0.1));
  CHECK(r.translation.min == Approx(0.1));
  CHECK(r.rotation_deg.max < 1e-9);

  RpeOptions frames;
  frames.unit = DeltaUnit::kFrames;
  frames.delta = 5;  // 0.5 s
  const RpeResult f = computeRpe(estimate, reference, frames);
  CHECK(f.pairs == 96);
  CHECK(f.translation.mean == Approx(0.05));

  // A heading that drifts 0.01 rad per 0.1 s step: 0.1 rad (5.73°) per second of rotation error.
  std::vector<TumPose> drifting = reference;
  for (std::size_t k = 0; k < drifting.size(); ++k)
    drifting[k] =
        TumPose::fromPlanar(drifting[k].stamp_ns, Pose2(0.1 * static_cast<double>(k), 0, 0.01 * k));
  const RpeResult d = computeRpe(drifting, reference);
  CHECK(d.rotation_deg.rmse == Approx(0.1 * 180 / pi));
  CHECK(d.rotation_deg.median == Approx(0.1 * 180 / pi));
}

TEST_CASE("RPE option and data errors are MetricErrors", "[eval][rpe]") {
  const auto traj = planarLoop(5, 10);
  RpeOptions bad;
  bad.delta = 0;
  CHECK_THROWS_AS(computeRpe(traj, traj, bad), MetricError);
  bad.delta = 1.5;
  bad.unit = DeltaUnit::kFrames;
  CHECK_THROWS_AS(computeRpe(traj, traj, bad), MetricError);
  RpeOptions too_long;
  too_long.delta = 60;
  CHECK_THROWS_AS(computeRpe(traj, traj, too_long), MetricError);
  CHECK_THROWS_AS(computeRpe(traj, {traj[0]}), MetricError);
  auto far = traj;
  for (auto& p : far) p.stamp_ns += 1000 * kSec;  // another time base
  CHECK_THROWS_AS(computeRpe(far, traj), MetricError);
}

TEST_CASE("planar trajectory interpolates on SE(2), reports outside and gaps", "[eval][metrics]") {
  std::vector<TumPose> poses{TumPose::fromPlanar(0, Pose2(0, 0, 3.0)),
                             TumPose::fromPlanar(2 * kSec, Pose2(2, 4, -3.0)),
                             TumPose::fromPlanar(10 * kSec, Pose2(10, 4, -3.0))};
  const PlanarTrajectory traj(poses);
  Pose2 p;
  REQUIRE(traj.at(kSec, 0, p) == PlanarTrajectory::Lookup::kOk);
  CHECK(p.x == Approx(1));
  CHECK(p.y == Approx(2));
  CHECK(std::abs(p.theta) == Approx(pi));  // across ±π, not through 0
  REQUIRE(traj.at(2 * kSec, 0, p) == PlanarTrajectory::Lookup::kOk);
  CHECK(p.x == 2);
  CHECK(traj.at(-1, 0, p) == PlanarTrajectory::Lookup::kOutside);
  CHECK(traj.at(10 * kSec + 1, 0, p) == PlanarTrajectory::Lookup::kOutside);
  CHECK(traj.at(5 * kSec, 7 * kSec, p) == PlanarTrajectory::Lookup::kInGap);
  CHECK(traj.at(5 * kSec, 8 * kSec, p) == PlanarTrajectory::Lookup::kOk);
  CHECK(traj.at(kSec, 7 * kSec, p) == PlanarTrajectory::Lookup::kOk);

  // Repeated stamps (a stalled clock): times after them start from the last pose stamped so.
  const PlanarTrajectory stalled(
      {TumPose::fromPlanar(0, Pose2(0, 0, 0)), TumPose::fromPlanar(kSec, Pose2(1, 0, 0)),
       TumPose::fromPlanar(kSec, Pose2(3, 0, 0)), TumPose::fromPlanar(2 * kSec, Pose2(5, 0, 0))});
  REQUIRE(stalled.at(kSec / 2, 0, p) == PlanarTrajectory::Lookup::kOk);
  CHECK(p.x == Approx(0.5));
  REQUIRE(stalled.at(3 * kSec / 2, 0, p) == PlanarTrajectory::Lookup::kOk);
  CHECK(p.x == Approx(4));
}

TEST_CASE("relations metric: frame convention of the relations", "[eval][relations]") {
  // At t=1 the robot is at (1, 0) facing +y; at t=2 it is 1 m further along +y. In its own frame
  // at t=1 that is 1 m straight ahead: δ = (1, 0, 0).
  const std::vector<TumPose> traj{TumPose::fromPlanar(kSec, Pose2(1, 0, pi / 2)),
                                  TumPose::fromPlanar(2 * kSec, Pose2(1, 1, pi / 2))};
  const RelationsResult right = computeRelationsError(traj, {{kSec, 2 * kSec, Pose2(1, 0, 0)}});
  CHECK(right.matched == 1);
  CHECK(right.translation.mean < 1e-12);
  const RelationsResult wrong = computeRelationsError(traj, {{kSec, 2 * kSec, Pose2(0, 1, 0)}});
  CHECK(wrong.translation.mean == Approx(std::sqrt(2.0)));
  const RelationsResult turned = computeRelationsError(traj, {{kSec, 2 * kSec, Pose2(1, 0, 0.1)}});
  CHECK(turned.translation.mean < 1e-12);
  CHECK(turned.rotation_deg.mean == Approx(0.1 * 180 / pi));
  CHECK(turned.rotation_squared_deg.mean == Approx(std::pow(0.1 * 180 / pi, 2)));
}

TEST_CASE("relations metric on a trajectory with a known jump", "[eval][relations]") {
  // The truth, sampled at 10 Hz; relations 2.33 s apart at times between samples (so they are
  // interpolated). The estimate equals the truth but jumps 0.2 m sideways in the world between
  // the samples at 30.0 s and 30.1 s: relations across the jump have |e_xy| = 0.2 m and e_θ = 0
  // (e = x(t2)⁻¹ ⊕ shift ⊕ x(t2) is a pure translation of the shift's length), the others 0.
  const auto truth = planarLoop(60, 10, 0);
  const PlanarTrajectory truth_traj(truth);
  std::vector<TumPose> estimate = truth;
  for (auto& p : estimate)
    if (p.stamp_ns > 30 * kSec) p.position.y() += 0.2;
  std::vector<PoseRelation> relations;
  std::size_t crossing = 0;
  for (int k = 0; k < 45; ++k) {
    const std::int64_t t1 = k * kSec + kSec / 4, t2 = t1 + 233 * kSec / 100;
    Pose2 a, b;
    REQUIRE(truth_traj.at(t1, 0, a) == PlanarTrajectory::Lookup::kOk);
    REQUIRE(truth_traj.at(t2, 0, b) == PlanarTrajectory::Lookup::kOk);
    relations.push_back({t1, t2, between(a, b)});
    if (t1 < 30 * kSec && t2 > 30 * kSec + kSec / 10) ++crossing;
  }
  REQUIRE(crossing == 2);  // 28.25 -> 30.58 and 29.25 -> 31.58
  const RelationsResult r = computeRelationsError(estimate, relations);
  CHECK(r.matched == 45);
  CHECK(r.outside == 0);
  const double n = 45;
  CHECK(r.translation.mean == Approx(0.2 * crossing / n).margin(1e-9));
  CHECK(r.translation_squared.mean == Approx(0.04 * crossing / n).margin(1e-9));
  CHECK(r.rotation_deg.max < 1e-9);
  const double mean = 0.2 * crossing / n;
  const double var = (crossing * std::pow(0.2 - mean, 2) + (n - crossing) * mean * mean) / (n - 1);
  CHECK(r.translation.std == Approx(std::sqrt(var)));
}

TEST_CASE("relations metric counts relations outside the trajectory or in its gaps",
          "[eval][relations]") {
  std::vector<TumPose> traj;
  for (int k = 0; k <= 10; ++k) traj.push_back(TumPose::fromPlanar(k * kSec, Pose2(k, 0, 0)));
  for (int k = 40; k <= 50; ++k) traj.push_back(TumPose::fromPlanar(k * kSec, Pose2(k, 0, 0)));
  const std::vector<PoseRelation> relations{
      {1 * kSec, 2 * kSec, Pose2(1, 0, 0)},     // fine
      {8 * kSec, 42 * kSec, Pose2(34, 0, 0)},   // fine: only its ends must be sampled
      {20 * kSec, 45 * kSec, Pose2(25, 0, 0)},  // starts in the 30 s gap
      {45 * kSec, 60 * kSec, Pose2(15, 0, 0)},  // ends after the trajectory
      {-5 * kSec, 1 * kSec, Pose2(6, 0, 0)},    // starts before it
  };
  RelationsOptions options;
  options.max_gap_s = 20;
  const RelationsResult r = computeRelationsError(traj, relations, options);
  CHECK(r.relations == 5);
  CHECK(r.matched == 2);
  CHECK(r.outside == 2);
  CHECK(r.in_gap == 1);
  options.max_gap_s = 0;  // no limit: the straight line interpolates exactly
  const RelationsResult all = computeRelationsError(traj, relations, options);
  CHECK(all.matched == 3);
  CHECK(all.translation.max < 1e-9);

  // A trajectory in another time base: shifted by 1000 s, then brought back with the offset.
  auto late = traj;
  for (auto& p : late) p.stamp_ns -= 1000 * kSec;
  CHECK_THROWS_AS(computeRelationsError(late, relations), MetricError);
  options.time_offset_s = 1000;
  CHECK(computeRelationsError(late, relations, options).matched == 3);
}

TEST_CASE("relations metric keeps every relation's error and splits off too fast relations",
          "[eval][relations]") {
  // Straight along x at 1 m/s, a pose a second: interpolation is exact.
  std::vector<TumPose> traj;
  for (int k = 0; k <= 10; ++k) traj.push_back(TumPose::fromPlanar(k * kSec, Pose2(k, 0, 0)));
  const std::vector<PoseRelation> relations{
      {1 * kSec, 2 * kSec, Pose2(1, 0, 0)},                 // 1 m/s (the limit: consistent), e = 0
      {2 * kSec, 4 * kSec, Pose2(2.5, 0, 0)},               // 1.25 m/s: inconsistent, e = 0.5 m
      {5 * kSec, 5 * kSec + kSec / 2, Pose2(0.5, 0, 0.1)},  // 1 m/s, e = 0.1 rad only
      {6 * kSec, 6 * kSec, Pose2(0.3, 0, 0)},               // no time: infinitely fast, e = 0.3 m
      {20 * kSec, 21 * kSec, Pose2(1, 0, 0)},               // after the trajectory: not matched
      {7 * kSec, 8 * kSec, Pose2(0, 0, 0)},                 // standing still, e = 1 m
  };
  RelationsOptions options;
  const RelationsResult off = computeRelationsError(traj, relations, options);
  CHECK(off.matched == 5);
  CHECK(off.inconsistent == 0);
  CHECK(off.translation.mean == Approx(0.36));
  CHECK(off.consistent_translation.count == 5);
  CHECK(off.consistent_translation.mean == Approx(0.36));
  CHECK(off.consistent_rotation_deg.mean == Approx(off.rotation_deg.mean));

  REQUIRE(off.errors.size() == 6);
  CHECK(off.errors[1].t1_ns == 2 * kSec);
  CHECK(off.errors[1].t2_ns == 4 * kSec);
  CHECK(off.errors[1].matched);
  CHECK(off.errors[1].translation == Approx(0.5));
  CHECK(off.errors[1].speed == Approx(1.25));
  CHECK(off.errors[2].translation == Approx(0).margin(1e-12));
  CHECK(off.errors[2].rotation_rad == Approx(0.1));
  CHECK(std::isinf(off.errors[3].speed));
  CHECK(off.errors[3].translation == Approx(0.3));
  CHECK_FALSE(off.errors[4].matched);
  CHECK(off.errors[4].translation == 0);
  CHECK(off.errors[5].speed == 0);
  for (const RelationError& e : off.errors) CHECK(e.consistent);

  options.max_speed = 1.0;
  const RelationsResult r = computeRelationsError(traj, relations, options);
  // The headline figures stay over all matched relations.
  CHECK(r.matched == 5);
  CHECK(r.translation.mean == off.translation.mean);
  CHECK(r.translation.std == off.translation.std);
  CHECK(r.rotation_deg.mean == off.rotation_deg.mean);
  CHECK(r.translation_squared.mean == off.translation_squared.mean);
  // Relations 1 and 3 are inconsistent; 0, 2 and 5 remain: |e_xy| = 0, 0, 1 and e_θ = 0, 0.1, 0.
  CHECK(r.inconsistent == 2);
  CHECK_FALSE(r.errors[1].consistent);
  CHECK_FALSE(r.errors[3].consistent);
  CHECK(r.errors[0].consistent);
  CHECK(r.errors[4].consistent);  // unmatched, but 1 m/s
  CHECK(r.consistent_translation.count == 3);
  CHECK(r.consistent_translation.mean == Approx(1.0 / 3));
  CHECK(r.consistent_translation.std == Approx(std::sqrt(1.0 / 3)));
  CHECK(r.consistent_translation_squared.mean == Approx(1.0 / 3));
  CHECK(r.consistent_rotation_deg.mean == Approx(0.1 * 180 / pi / 3));
  CHECK(r.consistent_rotation_squared_deg.mean == Approx(std::pow(0.1 * 180 / pi, 2) / 3));

  options.max_speed = -1;
  CHECK_THROWS_AS(computeRelationsError(traj, relations, options), MetricError);
  options.max_speed = std::nan("");
  CHECK_THROWS_AS(computeRelationsError(traj, relations, options), MetricError);

  // Bins of 2 s from the earliest t1 (1 s), matched relations only; the unmatched relation at
  // 20 s still extends the bins (to line up with other trajectories on the same relations).
  const std::vector<RelationsBin> bins = binRelationErrors(r.errors, 2.0);
  REQUIRE(bins.size() == 10);  // t1 − 1 s = 0, 1 | - | 4, 5 | 6 | - ... | 19
  for (std::size_t k = 0; k < bins.size(); ++k) CHECK(bins[k].start_s == Approx(2.0 * k));
  CHECK(bins[0].count == 2);
  CHECK(bins[0].translation_mean == Approx(0.25));
  CHECK(bins[0].rotation_mean_deg == Approx(0).margin(1e-12));
  CHECK(bins[1].count == 0);
  CHECK(bins[1].translation_mean == 0);
  CHECK(bins[2].count == 2);
  CHECK(bins[2].translation_mean == Approx(0.15));
  CHECK(bins[2].rotation_mean_deg == Approx(0.05 * 180 / pi));
  CHECK(bins[3].count == 1);
  CHECK(bins[3].translation_mean == Approx(1.0));
  for (std::size_t k = 4; k < bins.size(); ++k) CHECK(bins[k].count == 0);
  // One bin wider than the span holds every matched relation.
  const auto one = binRelationErrors(r.errors, 100);
  REQUIRE(one.size() == 1);
  CHECK(one[0].count == 5);
  CHECK(one[0].translation_mean == Approx(r.translation.mean));
  CHECK(one[0].rotation_mean_deg == Approx(r.rotation_deg.mean));

  CHECK(binRelationErrors({}, 1.0).empty());
  CHECK_THROWS_AS(binRelationErrors(r.errors, 0), MetricError);
  CHECK_THROWS_AS(binRelationErrors(r.errors, -1), MetricError);
  CHECK_THROWS_AS(binRelationErrors(r.errors, std::nan("")), MetricError);
  CHECK_THROWS_AS(binRelationErrors(r.errors, std::numeric_limits<double>::infinity()),
                  MetricError);
  CHECK_THROWS_AS(binRelationErrors(r.errors, 1e-9), MetricError);  // 1.9e10 bins
}

TEST_CASE("landmark error after rigid alignment, associated by id", "[eval][landmarks]") {
  std::vector<Landmark> reference{{1, {0, 0}}, {2, {4, 0}}, {3, {4, 3}}, {7, {-2, 5}}};
  std::vector<Landmark> estimate;
  const Pose2 frame(10, -5, 1.0);
  for (const auto& lm : reference)
    if (lm.id != 7) estimate.push_back({lm.id, frame * lm.position});
  estimate.push_back({99, {1, 1}});  // not in the reference
  const LandmarkResult r = computeLandmarkError(estimate, reference);
  CHECK(r.pairs == 3);
  CHECK(r.estimate_landmarks == 4);
  CHECK(r.reference_landmarks == 4);
  CHECK(r.error.max < 1e-9);

  // A square whose corners are pushed outwards: 0.1 m each after the best rigid alignment.
  std::vector<Landmark> square{{1, {1, 1}}, {2, {-1, 1}}, {3, {-1, -1}}, {4, {1, -1}}};
  std::vector<Landmark> pushed;
  for (const auto& lm : square)
    pushed.push_back({lm.id, frame * (lm.position + 0.1 * lm.position.normalized())});
  const LandmarkResult s = computeLandmarkError(pushed, square);
  CHECK(s.error.rmse == Approx(0.1));
  CHECK(s.error.median == Approx(0.1));
  CHECK(computeLandmarkError(pushed, square, /*scale=*/true).error.max < 1e-9);

  CHECK_THROWS_AS(computeLandmarkError({{5, {0, 0}}}, square), MetricError);
}

TEST_CASE("landmark files round-trip and malformed lines name file:line", "[eval][landmarks]") {
  const auto dir = tessera::test::scratchDir("landmark_io");
  const std::vector<Landmark> lms{{3, {1.25, -0.1}}, {-4, {1e-7, 123456.789}}};
  writeLandmarks(dir / "lm.txt", lms);
  const auto back = readLandmarks(dir / "lm.txt");
  REQUIRE(back.size() == 2);
  CHECK(back[1].id == -4);
  CHECK(back[1].position == lms[1].position);

  auto errorOf = [](const std::string& text) -> std::string {
    try {
      parseLandmarks(text, "m.txt");
    } catch (const LandmarkFileError& e) {
      return e.what();
    }
    return "";
  };
  CHECK(errorOf("# c\n\n1 2 3\n  \t\n").empty());
  CHECK_THAT(errorOf("1 2 3\n2 3\n"), Catch::Contains("m.txt:2:") && Catch::Contains("found 2"));
  CHECK_THAT(errorOf("1 2 3 4\n"), Catch::Contains("m.txt:1:") && Catch::Contains("more"));
  CHECK_THAT(errorOf("a 2 3\n"), Catch::Contains("integer id") && Catch::Contains("'a'"));
  CHECK_THAT(errorOf("1.5 2 3\n"), Catch::Contains("integer id"));
  CHECK_THAT(errorOf("1 nan 3\n"), Catch::Contains("for x"));
  CHECK_THAT(errorOf("1 2 1e999\n"), Catch::Contains("for y"));
  CHECK_THAT(errorOf("1 2 3\n\n1 4 5\n"), Catch::Contains("m.txt:3:") &&
                                              Catch::Contains("duplicate landmark id 1") &&
                                              Catch::Contains("line 1"));
  CHECK_THROWS_AS(readLandmarks(dir / "absent.txt"), LandmarkFileError);
}

TEST_CASE("checkLoops leaves loops without reference unchecked and counts NaN loops false",
          "[evaluation]") {
  std::vector<mapping::TumPose> ref;
  for (int i = 0; i < 5; ++i)
    ref.push_back({i * 1'000'000'000LL, Eigen::Vector3d(i, 0, 0), Eigen::Quaterniond::Identity()});
  const Pose3 back{Eigen::Vector3d(-3, 0, 0), Eigen::Quaterniond::Identity()};
  Pose3 broken = back;
  broken.t.x() = std::nan("");
  const std::vector<RelativeMeasurement> loops = {
      {4'000'000'000LL, 1'000'000'000LL, back},    // true
      {4'000'000'000LL, 1'000'000'000LL, broken},  // NaN: false, never true
      {9'000'000'000LL, 1'000'000'000LL, back}};   // no reference pose at 9 s
  const LoopCheckResult r = checkLoops(loops, ref);
  CHECK(r.loops == 3);
  CHECK(r.checked == 2);
  CHECK(r.false_loops == 1);
  CHECK(r.false_indices == std::vector<std::size_t>{1});
  CHECK(checkLoops(loops, {}).checked == 0);
}

TEST_CASE("heading drift: unaligned, relative to the first pose, unwrapped past pi",
          "[evaluation][heading]") {
  using tessera::mapping::TumPose;
  std::vector<TumPose> estimate, reference;
  // The reference turns at 0.5 rad/s for 20 s (several wraps); the estimate, offset by a
  // constant 1 rad (its own frame), turns 2 % faster: the error grows to 0.2 rad at the end.
  for (int k = 0; k <= 200; ++k) {
    const double t = 0.1 * k;
    const std::int64_t ns = static_cast<std::int64_t>(k) * 100'000'000;
    reference.push_back(TumPose::fromPlanar(ns, {0.1 * k, 0, 0.5 * t}));
    estimate.push_back(TumPose::fromPlanar(ns, {0.2 * k, 3, 1.0 + 0.51 * t}));
  }
  const auto r = tessera::evaluation::computeHeadingDrift(estimate, reference);
  CHECK(r.pairs == 201);
  CHECK(r.duration_s == Approx(20));
  const double deg = 180.0 / std::numbers::pi;
  CHECK(r.final_deg == Approx(0.2 * deg));
  CHECK(r.final_signed_deg == Approx(0.2 * deg));
  CHECK(r.error_deg.max == Approx(0.2 * deg));
  // |e| grows linearly from 0: RMS = final / sqrt(3) for many samples.
  CHECK(r.error_deg.rmse == Approx(0.2 * deg / std::sqrt(3.0)).epsilon(0.01));

  // A drift beyond pi is not folded back: 0.2 rad/s too fast over 20 s is 4 rad.
  for (int k = 0; k <= 200; ++k)
    estimate[k] = TumPose::fromPlanar(reference[k].stamp_ns, {0, 0, 0.7 * 0.1 * k});
  CHECK(tessera::evaluation::computeHeadingDrift(estimate, reference).final_deg ==
        Approx(4.0 * deg));
  CHECK_THROWS_AS(tessera::evaluation::computeHeadingDrift({}, reference),
                  tessera::evaluation::MetricError);
}

TEST_CASE("an alignment's unapply undoes apply", "[evaluation]") {
  Alignment a;
  a.rotation = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  a.translation = {3, -2, 0.5};
  a.scale = 1.3;
  const Eigen::Vector3d p(1.5, -4, 2);
  CHECK((a.unapply(a.apply(p)) - p).norm() < 1e-12);
  CHECK((a.apply(a.unapply(p)) - p).norm() < 1e-12);
}
