// Tests for the branch-and-bound correlative matcher and the loop-closure verifier. Worlds are
// line segments: grids are mapped by ray casting scans into an OccupancyGrid (as a submap would
// be), probe scans are ray cast exactly from a known pose, so the answer is known.
#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>
#include <tessera/scan_matching/correlative_matcher.hpp>

#include "../segment_world.hpp"

#include <catch2/catch.hpp>

#include <Eigen/Core>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <stdexcept>
#include <vector>

using tessera::angleDiff;
using tessera::Pose2;
using tessera::grid::OccupancyGrid;
using tessera::grid::OccupancyMap;
using tessera::grid::RangeScan;
using tessera::scan_matching::CorrelativeMatcher;
using tessera::scan_matching::CorrelativeMatcherOptions;
using tessera::scan_matching::CorrelativeMatchResult;
using tessera::scan_matching::GridView;
using tessera::scan_matching::LoopClosureVerifier;
using tessera::scan_matching::LoopRejection;
using tessera::scan_matching::MatchGrid;
using tessera::scan_matching::MatchStatus;
using tessera::scan_matching::SearchWindow;

namespace {
constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

using Walls = tessera::test::SegmentWorld;

constexpr int kBeams = 720;  // full circle, 0.5° apart
constexpr double kMaxRange = 12.0;

/// A full-circle scan's ranges from `pose` (+inf beyond max_range), with Gaussian noise.
std::vector<float> castRanges(const Walls& walls, const Pose2& pose, double max_range,
                              std::mt19937_64& rng, double noise) {
  std::normal_distribution<double> n(0.0, noise);
  std::vector<float> ranges(kBeams);
  for (int k = 0; k < kBeams; ++k) {
    const double r = tessera::test::castRay(walls, pose.translation(),
                                            pose.theta + k * 2.0 * std::numbers::pi / kBeams);
    ranges[static_cast<std::size_t>(k)] =
        r < max_range ? static_cast<float>(r + n(rng)) : std::numeric_limits<float>::infinity();
  }
  return ranges;
}

/// The scan's returns as points in the robot frame (every `stride`-th beam).
std::vector<Eigen::Vector2d> scanPoints(const Walls& walls, const Pose2& pose, double max_range,
                                        std::mt19937_64& rng, int stride = 2, double noise = 0.01) {
  const auto ranges = castRanges(walls, pose, max_range, rng, noise);
  std::vector<Eigen::Vector2d> pts;
  for (int k = 0; k < kBeams; k += stride) {
    const double r = ranges[static_cast<std::size_t>(k)];
    if (!std::isfinite(r)) continue;
    const double a = k * 2.0 * std::numbers::pi / kBeams;
    pts.emplace_back(r * std::cos(a), r * std::sin(a));
  }
  return pts;
}

/// The occupancy map a submap builder would hold after scans from `poses`.
OccupancyMap mapWalls(const Walls& walls, const std::vector<Pose2>& poses, double max_range) {
  OccupancyGrid grid;
  std::mt19937_64 rng(7);
  for (const Pose2& p : poses) {
    const auto ranges = castRanges(walls, p, max_range, rng, 0.005);
    const RangeScan scan{ranges, 0.0, 2.0 * std::numbers::pi / kBeams, 0.05, max_range};
    grid.insertScan(scan, p, {max_range, max_range});
  }
  return grid.toOccupancyMap();
}

void addLoop(Walls& w, const Pose2& frame, const std::vector<Eigen::Vector2d>& corners) {
  for (std::size_t i = 0; i < corners.size(); ++i)
    w.push_back({frame * corners[i], frame * corners[(i + 1) % corners.size()]});
}

void addBox(Walls& w, const Pose2& frame, double cx, double cy, double hx, double hy) {
  addLoop(w, frame,
          {{cx - hx, cy - hy}, {cx + hx, cy - hy}, {cx + hx, cy + hy}, {cx - hx, cy + hy}});
}

// Room A: a pentagon with furniture, turned so no wall is axis-aligned.
const Pose2 kRoomA(0.4, -0.3, 0.25);
Walls roomA() {
  Walls w;
  addLoop(w, kRoomA, {{0, 0}, {9, 0}, {9, 6}, {5.5, 7.5}, {0, 7.5}});
  addBox(w, kRoomA, 2.5, 2.0, 0.6, 0.4);
  addBox(w, kRoomA, 6.5, 4.8, 0.3, 0.3);
  addBox(w, kRoomA, 7.8, 1.2, 0.5, 0.7);
  addBox(w, kRoomA, 1.5, 6.6, 0.9, 0.2);
  return w;
}
std::vector<Pose2> roomAPoses() {
  std::vector<Pose2> out;
  for (const Pose2& p : {Pose2(1.2, 4.0, 0.0), Pose2(4.5, 3.5, 1.0), Pose2(4.5, 1.2, 2.0),
                         Pose2(7.0, 3.2, -1.0), Pose2(4.0, 6.3, 3.0), Pose2(1.0, 1.0, 0.5)})
    out.push_back(kRoomA * p);
  return out;
}

// Room B: an L-shaped hall of other proportions, nothing like room A.
Walls roomB() {
  Walls w;
  const Pose2 f(0.0, 0.0, 0.0);
  addLoop(w, f, {{0, 0}, {4, 0}, {4, 3}, {11, 3}, {11, 6.5}, {0, 6.5}});
  addBox(w, f, 7.0, 4.8, 0.2, 0.2);
  addBox(w, f, 9.5, 4.8, 0.2, 0.2);
  addBox(w, f, 2.0, 1.5, 0.5, 0.5);
  return w;
}

// A long straight corridor along x, 2 m wide, longer than the laser reaches.
Walls corridor() {
  return {{{-20.0, -1.0}, {20.0, -1.0}}, {{-20.0, 1.0}, {20.0, 1.0}}};
}

double translationError(const Pose2& a, const Pose2& b) {
  return (a.translation() - b.translation()).norm();
}

/// Every candidate the matcher considers, scored independently through score(): the lattice of
/// initial + whole cells and whole angular steps (the same lattice as the matcher's, spelled
/// out here in the grid's frame, whose origin has no yaw).
struct BruteForce {
  double best = -1.0;
  Pose2 best_pose;
  std::vector<std::pair<Pose2, double>> all;
};
BruteForce bruteForce(const CorrelativeMatcher& m, const MatchGrid& grid,
                      const std::vector<Eigen::Vector2d>& pts, const Pose2& initial,
                      const SearchWindow& win, double step) {
  REQUIRE(grid.origin().theta == 0.0);
  const double res = grid.resolution();
  const int w = static_cast<int>(std::ceil(win.linear / res));
  const int na = static_cast<int>(std::ceil(win.angular / step));
  BruteForce out;
  for (int j = -na; j <= na; ++j)
    for (int y = -w; y <= w; ++y)
      for (int x = -w; x <= w; ++x) {
        const Pose2 p(initial.x + x * res, initial.y + y * res, initial.theta + j * step);
        const double s = m.score(grid, pts, p);
        out.all.emplace_back(p, s);
        if (s > out.best) {
          out.best = s;
          out.best_pose = p;
        }
      }
  return out;
}

}  // namespace

TEST_CASE("correlative matcher finds a pose 1.5 m and 15 deg off", "[correlative_matcher]") {
  const Walls walls = roomA();
  const OccupancyMap map = mapWalls(walls, roomAPoses(), kMaxRange);
  const CorrelativeMatcher matcher;
  const MatchGrid grid = matcher.precompute(GridView::of(map));
  REQUIRE_FALSE(grid.empty());

  std::mt19937_64 rng(11);
  for (const Pose2& truth_in_room : {Pose2(3.0, 4.5, 0.3), Pose2(6.0, 2.5, -2.0)}) {
    const Pose2 truth = kRoomA * truth_in_room;
    const auto pts = scanPoints(walls, truth, kMaxRange, rng);
    // 1.2 m and −0.9 m: 1.5 m away, turned 15°.
    const Pose2 initial(truth.x + 1.2, truth.y - 0.9, truth.theta + 15 * kDeg);
    const CorrelativeMatchResult r = matcher.match(grid, pts, initial, {1.8, 20 * kDeg});
    INFO("score " << r.score << " second " << r.second_best_score);
    REQUIRE(r.matched());
    CHECK(translationError(r.pose, truth) < 0.08);
    CHECK(std::abs(angleDiff(r.pose.theta, truth.theta)) < 1.0 * kDeg);
    CHECK(r.score > 0.7);
    CHECK(r.second_best_score < 0.8 * r.score);
    CHECK(r.points_used == static_cast<int>(pts.size()));
    // Well constrained: about the lattice floor, far below the sampled span's uniform variance.
    CHECK(std::sqrt(r.covariance(0, 0)) < 0.05);
    CHECK(std::sqrt(r.covariance(1, 1)) < 0.05);
    CHECK(std::sqrt(r.covariance(2, 2)) < 1.0 * kDeg);

    LoopClosureVerifier verifier;
    const auto v = verifier.verify(r, initial, Eigen::Vector3d(1.0, 1.0, 0.3).asDiagonal());
    CHECK(v.accepted);
    CHECK(verifier.counts().accepted == 1);
  }
}

TEST_CASE("correlative matcher handles a grid origin with yaw", "[correlative_matcher]") {
  // The same map moved rigidly by P: the scan taken at P·truth must be found at P·truth.
  const Walls walls = roomA();
  OccupancyMap map = mapWalls(walls, roomAPoses(), kMaxRange);
  const Pose2 moved(-3.0, 2.0, 0.7);
  map.origin = moved * map.origin;
  const CorrelativeMatcher matcher;
  std::mt19937_64 rng(5);
  const Pose2 truth = kRoomA * Pose2(4.0, 3.0, 1.2);
  const auto pts = scanPoints(walls, truth, kMaxRange, rng);
  const Pose2 truth_moved = moved * truth;
  const Pose2 initial(truth_moved.x - 0.6, truth_moved.y + 0.5, truth_moved.theta - 8 * kDeg);
  const auto r = matcher.match(GridView::of(map), pts, initial, {1.0, 10 * kDeg});
  REQUIRE(r.matched());
  CHECK(translationError(r.pose, truth_moved) < 0.08);
  CHECK(std::abs(angleDiff(r.pose.theta, truth_moved.theta)) < 1.0 * kDeg);
}

TEST_CASE("branch and bound equals exhaustive search on a small window", "[correlative_matcher]") {
  const Walls walls = roomA();
  const OccupancyMap map = mapWalls(walls, roomAPoses(), kMaxRange);
  CorrelativeMatcherOptions o;
  o.min_score = 0.3;
  o.second_best_min_ratio = 0.3;
  o.pyramid_depth = 4;  // several levels inside a 21-cell window
  const CorrelativeMatcher bnb(o);
  o.search = CorrelativeMatcherOptions::Search::kExhaustive;
  const CorrelativeMatcher exhaustive(o);
  const MatchGrid grid = bnb.precompute(GridView::of(map));

  std::mt19937_64 rng(3);
  for (const Pose2& truth_in_room : {Pose2(2.0, 3.5, 0.8), Pose2(5.0, 5.5, -1.5)}) {
    const Pose2 truth = kRoomA * truth_in_room;
    const auto pts = scanPoints(walls, truth, kMaxRange, rng, 4, 0.02);
    const Pose2 initial(truth.x + 0.23, truth.y - 0.31, truth.theta + 3 * kDeg);
    const SearchWindow win{0.5, 5 * kDeg};
    const auto r = bnb.match(grid, pts, initial, win);
    REQUIRE(r.matched());
    const BruteForce bf = bruteForce(bnb, grid, pts, initial, win, r.angular_step);
    CHECK(r.score == Approx(bf.best).margin(1e-12));
    CHECK(bnb.score(grid, pts, r.pose) == Approx(r.score).margin(1e-12));
    // Branch and bound must have pruned most of the lattice.
    CHECK(r.nodes_scored < static_cast<std::int64_t>(bf.all.size()) / 4);

    // Second best: the best lattice pose distinct from the match, if it reaches the floor.
    const double res = grid.resolution();
    const int excl_steps = static_cast<int>(std::floor(o.exclusion_angle / r.angular_step));
    double second = 0.0;
    for (const auto& [p, s] : bf.all) {
      const double d = translationError(p, r.pose) / res;
      const double turns = std::round(std::abs(angleDiff(p.theta, r.pose.theta)) / r.angular_step);
      const bool distinct =
          d * d > std::pow(o.exclusion_radius / res, 2) + 1e-6 || turns > excl_steps;
      if (distinct && s >= o.second_best_min_ratio * r.score && s > second) second = s;
    }
    CHECK(r.second_best_score == Approx(second).margin(1e-12));

    // The library's exhaustive mode agrees too (and scores every candidate, twice).
    const auto e = exhaustive.match(grid, pts, initial, win);
    CHECK(e.score == Approx(r.score).margin(1e-12));
    CHECK(e.second_best_score == Approx(r.second_best_score).margin(1e-12));
    CHECK(e.nodes_scored == 2 * static_cast<std::int64_t>(bf.all.size()));
  }
}

TEST_CASE("a scan from a different room is rejected", "[correlative_matcher]") {
  const Walls walls_a = roomA();
  const OccupancyMap map = mapWalls(walls_a, roomAPoses(), kMaxRange);
  CorrelativeMatcherOptions o;
  o.min_score = 0.2;  // let the matcher report what it finds; the verifier decides
  const CorrelativeMatcher matcher(o);
  const MatchGrid grid = matcher.precompute(GridView::of(map));
  LoopClosureVerifier verifier;
  const Eigen::Matrix3d prior_cov = Eigen::Vector3d(1.0, 1.0, 0.3).asDiagonal();

  std::mt19937_64 rng(9);
  int rejected = 0;
  const std::vector<Pose2> in_b = {Pose2(2.0, 4.5, 0.3), Pose2(8.0, 4.5, 2.5),
                                   Pose2(3.0, 5.0, -1.0)};
  for (const Pose2& pose_b : in_b) {
    const auto pts = scanPoints(roomB(), pose_b, kMaxRange, rng);
    // The robot believes it is in room A, at the centre.
    const Pose2 initial = kRoomA * Pose2(4.5, 3.5, pose_b.theta);
    const auto r = matcher.match(grid, pts, initial, {2.0, 20 * kDeg});
    const auto v = verifier.verify(r, initial, prior_cov);
    INFO("score " << r.score << " second " << r.second_best_score << " reason "
                  << toString(v.reason));
    CHECK_FALSE(v.accepted);
    CHECK((v.reason == LoopRejection::kLowScore || v.reason == LoopRejection::kAmbiguous ||
           v.reason == LoopRejection::kNoMatch));
    rejected += v.accepted ? 0 : 1;
  }
  const auto& c = verifier.counts();
  CHECK(c.candidates == in_b.size());
  CHECK(c.accepted == 0);
  CHECK(c.low_score + c.ambiguous + c.no_match == static_cast<std::size_t>(rejected));
}

TEST_CASE("a corridor scan is flagged ambiguous along the corridor", "[correlative_matcher]") {
  const Walls walls = corridor();
  std::vector<Pose2> poses;
  for (double x = -12.0; x <= 12.0; x += 3.0) poses.emplace_back(x, 0.1, 0.0);
  const double range = 6.0;  // the ends are out of reach
  const OccupancyMap map = mapWalls(walls, poses, range);
  const CorrelativeMatcher matcher;
  const MatchGrid grid = matcher.precompute(GridView::of(map));
  std::mt19937_64 rng(2);
  const Pose2 truth(0.7, -0.2, 0.05);
  const auto pts = scanPoints(walls, truth, range, rng);
  const Pose2 initial(truth.x + 0.4, truth.y + 0.3, truth.theta - 4 * kDeg);
  const auto r = matcher.match(grid, pts, initial, {1.5, 10 * kDeg});
  REQUIRE(r.matched());
  INFO("score " << r.score << " second " << r.second_best_score);
  // Across the corridor and in heading the match is right; along it, anything goes.
  CHECK(std::abs(r.pose.y - truth.y) < 0.08);
  CHECK(std::abs(angleDiff(r.pose.theta, truth.theta)) < 1.0 * kDeg);
  CHECK(r.second_best_score > 0.95 * r.score);
  CHECK(std::abs(r.second_best_pose.x - r.pose.x) > 0.45);
  CHECK(std::abs(r.second_best_pose.y - r.pose.y) < 0.1);
  CHECK(r.covariance(0, 0) > 20.0 * r.covariance(1, 1));

  LoopClosureVerifier verifier;
  const auto v = verifier.verify(r, initial, Eigen::Vector3d(1.0, 1.0, 0.3).asDiagonal());
  CHECK_FALSE(v.accepted);
  CHECK(v.reason == LoopRejection::kAmbiguous);
  CHECK(verifier.counts().ambiguous == 1);

  // With the ambiguity test off, the position spread along the corridor still rejects it.
  tessera::scan_matching::LoopClosureVerifierOptions spread_only;
  spread_only.max_ambiguity = 1.0;
  spread_only.max_position_sigma = 0.12;
  LoopClosureVerifier by_spread(spread_only);
  const auto u = by_spread.verify(r, initial, Eigen::Vector3d(1.0, 1.0, 0.3).asDiagonal());
  CHECK(u.reason == LoopRejection::kUnconstrained);
  CHECK(by_spread.counts().unconstrained == 1);
  spread_only.max_position_sigma = -1;
  CHECK_THROWS_AS(LoopClosureVerifier(spread_only), std::invalid_argument);
}

TEST_CASE("loop verifier rejects a match inconsistent with the prior", "[correlative_matcher]") {
  // A false loop by construction: the match is good but lies 1.5 m from where a confident prior
  // (σ 0.2 m) puts the robot.
  const Walls walls = roomA();
  const OccupancyMap map = mapWalls(walls, roomAPoses(), kMaxRange);
  const CorrelativeMatcher matcher;
  std::mt19937_64 rng(4);
  const Pose2 truth = kRoomA * Pose2(3.0, 4.5, 0.3);
  const auto pts = scanPoints(walls, truth, kMaxRange, rng);
  const Pose2 prior(truth.x + 1.2, truth.y - 0.9, truth.theta);
  const auto r = matcher.match(GridView::of(map), pts, prior, {1.8, 10 * kDeg});
  REQUIRE(r.matched());

  LoopClosureVerifier verifier;
  const Eigen::Matrix3d tight = Eigen::Vector3d(0.04, 0.04, 0.01).asDiagonal();
  const auto v = verifier.verify(r, prior, tight);
  CHECK_FALSE(v.accepted);
  CHECK(v.reason == LoopRejection::kInconsistent);
  CHECK(v.prior_sigmas == Approx(7.5).epsilon(0.1));
  // The same match under a loose prior is fine.
  const auto loose = verifier.verify(r, prior, Eigen::Vector3d(1.0, 1.0, 0.1).asDiagonal());
  CHECK(loose.accepted);
  CHECK(loose.prior_sigmas < 3.0);
  // A prior covariance that is not positive definite is a counted rejection, not a throw.
  Eigen::Matrix3d singular = tight;
  singular(2, 2) = 0.0;
  CHECK(verifier.verify(r, prior, singular).reason == LoopRejection::kBadPrior);
  Eigen::Matrix3d asymmetric = tight;
  asymmetric(0, 1) = 0.01;
  CHECK(verifier.verify(r, prior, asymmetric).reason == LoopRejection::kBadPrior);
  CHECK(verifier.verify(r, Pose2(kNaN, 0, 0), tight).reason == LoopRejection::kBadPrior);
  const auto& c = verifier.counts();
  CHECK(c.candidates == 5);
  CHECK(c.inconsistent == 1);
  CHECK(c.accepted == 1);
  CHECK(c.bad_prior == 3);
}

TEST_CASE("correlative matcher reports bad input without throwing", "[correlative_matcher]") {
  const Walls walls = roomA();
  const OccupancyMap map = mapWalls(walls, roomAPoses(), kMaxRange);
  const CorrelativeMatcher matcher;
  const MatchGrid grid = matcher.precompute(GridView::of(map));
  std::mt19937_64 rng(1);
  const Pose2 truth = kRoomA * Pose2(3.0, 4.5, 0.3);
  auto pts = scanPoints(walls, truth, kMaxRange, rng);
  const SearchWindow win{0.5, 5 * kDeg};

  SECTION("empty scan") {
    const auto r = matcher.match(grid, std::vector<Eigen::Vector2d>{}, truth, win);
    CHECK(r.status == MatchStatus::kEmptyScan);
    CHECK_FALSE(r.matched());
    CHECK(r.pose.x == truth.x);
  }
  SECTION("NaN and far points are dropped and counted") {
    const std::vector<Eigen::Vector2d> bad(5, Eigen::Vector2d(kNaN, 1.0));
    const auto r = matcher.match(grid, bad, truth, win);
    CHECK(r.status == MatchStatus::kEmptyScan);
    CHECK(r.points_dropped == 5);
    const std::size_t n = pts.size();
    pts.emplace_back(kNaN, kNaN);
    pts.emplace_back(std::numeric_limits<double>::infinity(), 0.0);
    pts.emplace_back(100.0, 0.0);  // beyond max_range
    const auto mixed = matcher.match(grid, pts, truth, win);
    CHECK(mixed.matched());
    CHECK(mixed.points_used == static_cast<int>(n));
    CHECK(mixed.points_dropped == 3);
  }
  SECTION("zero-size or inconsistent grid") {
    const auto r = matcher.match(GridView{}, pts, truth, win);
    CHECK(r.status == MatchStatus::kEmptyGrid);
    const MatchGrid none = matcher.precompute(GridView{});
    CHECK(none.empty());
    CHECK_FALSE(none.error().empty());
    GridView short_cells = GridView::of(map);
    short_cells.percent = short_cells.percent.first(10);
    CHECK(matcher.precompute(short_cells).empty());
    GridView bad_res = GridView::of(map);
    bad_res.resolution = 0.0;
    CHECK(matcher.match(bad_res, pts, truth, win).status == MatchStatus::kEmptyGrid);
  }
  SECTION("window not positive") {
    for (const SearchWindow& w :
         {SearchWindow{0.0, 0.1}, SearchWindow{-1.0, 0.1}, SearchWindow{0.5, -0.1},
          SearchWindow{kNaN, 0.1}, SearchWindow{0.5, std::numeric_limits<double>::infinity()}})
      CHECK(matcher.match(grid, pts, truth, w).status == MatchStatus::kBadWindow);
    // Zero angular window is a translation-only search, not an error.
    CHECK(matcher.match(grid, pts, truth, {0.3, 0.0}).matched());
  }
  SECTION("non-finite initial pose") {
    CHECK(matcher.match(grid, pts, Pose2(kNaN, 0.0, 0.0), win).status == MatchStatus::kBadPose);
  }
  SECTION("bad options throw") {
    CorrelativeMatcherOptions o;
    o.pyramid_depth = 11;
    CHECK_THROWS_AS(CorrelativeMatcher(o), std::invalid_argument);
    o = {};
    o.min_score = 1.5;
    CHECK_THROWS_AS(CorrelativeMatcher(o), std::invalid_argument);
    o = {};
    o.covariance_temperature = 0.0;
    CHECK_THROWS_AS(CorrelativeMatcher(o), std::invalid_argument);
    LoopClosureVerifier::Options v;
    v.max_ambiguity = 0.0;
    CHECK_THROWS_AS(LoopClosureVerifier(v), std::invalid_argument);
  }
  SECTION("an unmatched result is a counted rejection") {
    LoopClosureVerifier verifier;
    const auto r = matcher.match(grid, std::vector<Eigen::Vector2d>{}, truth, win);
    CHECK(verifier.verify(r, truth, Eigen::Matrix3d::Identity()).reason == LoopRejection::kNoMatch);
    CHECK(verifier.counts().no_match == 1);
  }
}

TEST_CASE("correlative matcher accepts float probability grids", "[correlative_matcher]") {
  // The same map as probabilities (NaN unknown) scores exactly as the int8 view.
  const Walls walls = roomA();
  const OccupancyMap map = mapWalls(walls, roomAPoses(), kMaxRange);
  std::vector<float> prob(map.cells.size());
  for (std::size_t i = 0; i < prob.size(); ++i)
    prob[i] = map.cells[i] < 0 ? std::numeric_limits<float>::quiet_NaN() : map.cells[i] / 100.0f;
  GridView fview{map.width, map.height, map.resolution, map.origin, {}, prob};
  const CorrelativeMatcher matcher;
  std::mt19937_64 rng(8);
  const Pose2 truth = kRoomA * Pose2(5.0, 3.0, 2.2);
  const auto pts = scanPoints(walls, truth, kMaxRange, rng);
  const Pose2 initial(truth.x - 0.5, truth.y + 0.4, truth.theta + 6 * kDeg);
  const auto a = matcher.match(GridView::of(map), pts, initial, {0.8, 8 * kDeg});
  const auto b = matcher.match(fview, pts, initial, {0.8, 8 * kDeg});
  REQUIRE(a.matched());
  REQUIRE(b.matched());
  CHECK(b.score == Approx(a.score).margin(1e-4));
  CHECK(translationError(a.pose, b.pose) < 1e-9);
}

TEST_CASE("MatchGrid reports the bytes it holds; check() tells a bad view without building",
          "[correlative_matcher]") {
  OccupancyMap map;
  map.width = 100;
  map.height = 60;
  map.resolution = 0.05;
  map.cells.assign(static_cast<std::size_t>(map.width * map.height), -1);
  for (int x = 10; x < 90; ++x) map.at(x, 30) = 100;
  CHECK(MatchGrid::check(GridView::of(map)).empty());
  for (const int depth : {0, 3, 7}) {
    const MatchGrid grid(GridView::of(map), depth, 0.1);
    REQUIRE(grid.depth() == depth);
    // Level h is padded by 2^h − 1 cells per axis; each cell is 1 byte (it was 2 with the
    // earlier 16-bit cells).
    std::size_t cells = 0;
    for (int h = 0; h <= depth; ++h)
      cells += static_cast<std::size_t>(map.width + (1 << h) - 1) *
               static_cast<std::size_t>(map.height + (1 << h) - 1);
    CHECK(grid.bytes() >= static_cast<std::size_t>(map.width * map.height * (depth + 1)));
    CHECK(grid.bytes() >= cells);
    CHECK(grid.bytes() < cells + 1024);  // the small overhead: object and level table
  }
  const MatchGrid none(GridView{}, 7, 0.1);
  CHECK(none.bytes() < 1024);
  GridView bad = GridView::of(map);
  bad.resolution = 0.0;
  CHECK_FALSE(MatchGrid::check(bad).empty());
  CHECK(MatchGrid::check(bad) == MatchGrid(bad, 7, 0.1).error());
  bad = GridView::of(map);
  bad.percent = bad.percent.first(10);
  CHECK(MatchGrid::check(bad) == "grid cell count does not match width x height");
}

TEST_CASE("MatchGrid stores percent cells exactly as 2p and unknown as its probability in 1/200",
          "[correlative_matcher]") {
  STATIC_REQUIRE(MatchGrid::kScale == 200);
  OccupancyMap map;
  map.width = 400;
  map.height = 400;
  map.resolution = 0.05;
  map.cells.resize(static_cast<std::size_t>(map.width * map.height));
  // Every ROS value −1..100 (and −128, another unknown) somewhere in the grid.
  for (std::size_t i = 0; i < map.cells.size(); ++i)
    map.cells[i] = static_cast<std::int8_t>(static_cast<int>(i % 103) - 2);
  map.cells[5] = -128;
  for (const double unknown : {0.1, 0.0, 1.0, 0.333}) {
    const MatchGrid grid(GridView::of(map), 7, unknown);
    REQUIRE(grid.depth() == 7);
    const int u = static_cast<int>(std::lround(unknown * MatchGrid::kScale));
    CHECK(static_cast<int>(grid.unknownValue()) == u);
    if (unknown == 0.1) CHECK(static_cast<int>(grid.unknownValue()) == 20);
    for (int y = 0; y < map.height; ++y)
      for (int x = 0; x < map.width; ++x) {
        const int p = map.at(x, y);
        const int want = p < 0 ? u : 2 * p;
        if (static_cast<int>(grid.at(0, x, y)) != want) {
          FAIL_CHECK("cell (" << x << ", " << y << ") = " << p << " % stores "
                              << static_cast<int>(grid.at(0, x, y)) << ", not " << want);
          return;
        }
      }
    CHECK(static_cast<int>(grid.at(0, -1, 0)) == u);  // outside the grid
    CHECK(static_cast<int>(grid.at(7, map.width, 0)) == u);
    // A score is the mean of stored values over kScale: exactly p / 100 on a p % cell.
    const CorrelativeMatcher matcher;
    const std::vector<Eigen::Vector2d> one{{0.0, 0.0}};
    const Pose2 on_50(map.origin.x + (52 + 0.5) * map.resolution,
                      map.origin.y + 0.5 * map.resolution, 0.0);  // cell (52, 0) holds 50 %
    REQUIRE(map.at(52, 0) == 50);
    CHECK(matcher.score(grid, one, on_50) == 0.5);
  }

  // Depth 7 costs under 10 bytes per grid cell (8 levels of 1 byte plus padding).
  const MatchGrid grid(GridView::of(map), 7, 0.1);
  CHECK(grid.bytes() < static_cast<std::size_t>(10 * map.width * map.height));
  CHECK(grid.bytes() > static_cast<std::size_t>(8 * map.width * map.height));

  // Float probabilities are rounded to the nearest 1/200; NaN is unknown.
  std::vector<float> prob = {0.0f,    1.0f,  0.5f, 0.1234f,
                             0.9976f, -0.5f, 2.0f, std::numeric_limits<float>::quiet_NaN()};
  const GridView fview{static_cast<int>(prob.size()), 1, 0.05, Pose2(), {}, prob};
  const MatchGrid fgrid(fview, 0, 0.1);
  const int want[] = {0, 200, 100, 25, 200, 0, 200, 20};
  for (int x = 0; x < static_cast<int>(prob.size()); ++x)
    CHECK(static_cast<int>(fgrid.at(0, x, 0)) == want[x]);
}
