// Tests for the laser scan matcher: beam preparation, the score / likelihood model, hill
// climbing, the match covariance, the improved-proposal fit and matching to per-cell hit points.
// Worlds are sets of line segments ray-cast exactly here, so the map is the only discretised thing.
// Longer than ~600 lines on purpose: one test file per source file (the tree is mirrored), and
// the matcher is the hot path every laser SLAM result rests on.
#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>
#include <tessera/grid/tiled_grid.hpp>

#include "../segment_world.hpp"
#include "scan_matcher_impl.hpp"  // templates for the fake grids below

#include <catch2/catch.hpp>

#include <Eigen/Dense>

#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <stdexcept>
#include <utility>
#include <vector>

using tessera::angleDiff;
using tessera::Pose2;
using tessera::grid::OccupancyGrid;
using tessera::grid::RangeScan;
using tessera::grid::TiledGrid;
using tessera::scan_matching::MatchResult;
using tessera::scan_matching::ProposalFit;
using tessera::scan_matching::ScanMatcher;
using tessera::scan_matching::ScanMatcherOptions;
using tessera::scan_matching::ScanPoints;

namespace {
constexpr double kDeg = std::numbers::pi / 180.0;
constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

using Segment = tessera::test::Segment;
using World = tessera::test::SegmentWorld;
using tessera::test::castRay;

struct Laser {
  double angle_min = -135 * kDeg;
  double angle_increment = 0.75 * kDeg;
  int beams = 361;
  double range_min = 0.1, range_max = 30.0;
  Pose2 mount{0.15, 0.05, 0.1};  // laser in base frame

  RangeScan view(const std::vector<float>& ranges) const {
    return {ranges, angle_min, angle_increment, range_min, range_max};
  }
};

std::vector<float> simulate(const World& world, const Laser& laser, const Pose2& base,
                            std::mt19937_64& rng, double noise = 0.01) {
  std::normal_distribution<double> n(0.0, noise);
  const Pose2 sensor = base * laser.mount;
  std::vector<float> ranges(static_cast<std::size_t>(laser.beams));
  for (int k = 0; k < laser.beams; ++k) {
    const double r = castRay(world, sensor.translation(),
                             sensor.theta + laser.angle_min + k * laser.angle_increment);
    ranges[static_cast<std::size_t>(k)] =
        r < laser.range_max ? static_cast<float>(r + n(rng)) : kInf;
  }
  return ranges;
}

void addPolygon(World& w, const std::vector<Eigen::Vector2d>& v) {
  for (std::size_t i = 0; i < v.size(); ++i) w.push_back({v[i], v[(i + 1) % v.size()]});
}

std::vector<Eigen::Vector2d> box(const Pose2& centre, double sx, double sy) {
  std::vector<Eigen::Vector2d> v;
  for (const auto& c : {Eigen::Vector2d(-sx, -sy), Eigen::Vector2d(sx, -sy),
                        Eigen::Vector2d(sx, sy), Eigen::Vector2d(-sx, sy)})
    v.push_back(centre * (0.5 * c));
  return v;
}

// The room, in its own frame, placed in the map by kRoomPose so no wall is axis-aligned.
const Pose2 kRoomPose(1.3, -0.7, 0.3);

World room() {
  World w;
  std::vector<Eigen::Vector2d> outline = {{0, 0}, {10, 0}, {10, 7}, {6, 8}, {0, 8}};
  for (auto& p : outline) p = kRoomPose * p;
  addPolygon(w, outline);
  for (const auto& b : {box({3, 3, 0.5}, 1.0, 0.6), box({6, 5.5, 0.2}, 0.4, 0.4),
                        box({8.2, 2.0, -0.3}, 0.8, 1.2), box({2.0, 6.5, 0.0}, 1.5, 0.3)}) {
    std::vector<Eigen::Vector2d> v = b;
    for (auto& p : v) p = kRoomPose * p;
    addPolygon(w, v);
  }
  return w;
}

std::vector<Pose2> roomMappingPoses() {
  std::vector<Pose2> poses;
  for (const Pose2& p :
       {Pose2(1.5, 4.5, 0.0), Pose2(4.5, 4.5, 1.0), Pose2(5.0, 2.0, 2.0), Pose2(7.0, 4.0, -1.0),
        Pose2(5.0, 7.0, 3.0), Pose2(1.5, 1.5, 0.5), Pose2(8.5, 6.0, -2.5), Pose2(3.5, 5.5, -0.7)})
    poses.push_back(kRoomPose * p);
  return poses;
}

template <class Grid = OccupancyGrid>
Grid mapOf(const World& world, const Laser& laser, const std::vector<Pose2>& poses,
           std::uint64_t seed = 1, Grid grid = Grid()) {
  std::mt19937_64 rng(seed);
  for (const Pose2& p : poses) {
    const std::vector<float> r = simulate(world, laser, p, rng);
    grid.insertScan(laser.view(r), p * laser.mount);
  }
  return grid;
}

/// A world, the laser that sees it and a map built from its scans at known poses.
struct Scene {
  World world;
  Laser laser;
  OccupancyGrid grid;

  Scene(World w, const std::vector<Pose2>& mapping_poses)
      : world(std::move(w)), grid(mapOf(world, laser, mapping_poses)) {}
  /// The points of a fresh noisy scan taken at `truth`.
  ScanPoints scan(const ScanMatcher& m, const Pose2& truth, std::mt19937_64& rng) const {
    return m.prepare(laser.view(simulate(world, laser, truth, rng)), laser.mount);
  }
};

Scene roomScene() {
  return Scene(room(), roomMappingPoses());
}

double translationError(const Pose2& a, const Pose2& b) {
  return (a.translation() - b.translation()).norm();
}

/// A dense grid of explicitly set cells, to check the matcher against a Grid other than
/// OccupancyGrid and to build exact cell patterns.
class FakeGrid {
 public:
  explicit FakeGrid(double res) : res_(res), cells_(kSide * kSide, 0.0f) {}
  double resolution() const { return res_; }
  Eigen::Vector2i worldToCell(const Eigen::Vector2d& p) const {
    return {static_cast<int>(std::floor(p.x() / res_)), static_cast<int>(std::floor(p.y() / res_))};
  }
  Eigen::Vector2d cellCenter(const Eigen::Vector2i& c) const {
    return (c.cast<double>() + Eigen::Vector2d(0.5, 0.5)) * res_;
  }
  float logOdds(const Eigen::Vector2i& c) const {
    if (c.x() < 0 || c.y() < 0 || c.x() >= kSide || c.y() >= kSide) return 0.0f;
    return cells_[static_cast<std::size_t>(c.y() * kSide + c.x())];
  }
  void set(int x, int y, float v) { cells_[static_cast<std::size_t>(y * kSide + x)] = v; }

 private:
  static constexpr int kSide = 64;
  double res_;
  std::vector<float> cells_;
};

ScanPoints onePoint(const Eigen::Vector2f& origin, const Eigen::Vector2f& end) {
  ScanPoints p;
  p.origin = origin;
  p.endpoints = {end};
  p.beams_total = 1;
  return p;
}
}  // namespace

TEST_CASE("ScanMatcher rejects invalid options", "[scan_matcher]") {
  auto with = [](auto edit) {
    ScanMatcherOptions o;
    edit(o);
    return o;
  };
  CHECK_NOTHROW(ScanMatcher(ScanMatcherOptions{}));
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.beam_step = 0; })), std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.kernel_radius = -1; })), std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.sigma = 0.0; })), std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.likelihood_sigma = kNaN; })),
                  std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.likelihood_gain = -1.0; })),
                  std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.linear_step = 0.0; })), std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.max_iterations = 0; })), std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.min_score_fraction = 1.5; })),
                  std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.proposal_steps = 0; })), std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.free_check_offset = kNaN; })),
                  std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.no_hit_distance = -0.1; })),
                  std::invalid_argument);
  CHECK_THROWS_AS(ScanMatcher(with([](auto& o) { o.no_hit_distance = kNaN; })),
                  std::invalid_argument);
}

TEST_CASE("prepare keeps valid beams as base-frame endpoints", "[scan_matcher]") {
  ScanMatcherOptions o;
  o.max_range = 5.0;
  const ScanMatcher matcher(o);
  // Beams at -90, 0, 90, 180 deg ... then invalid ones.
  const std::vector<float> ranges = {2.0f, 1.0f, 3.0f, 4.0f, kNaN, 0.05f, kInf, 10.0f, 6.0f, 0.0f};
  const RangeScan scan{ranges, -std::numbers::pi / 2, std::numbers::pi / 2, 0.1, 8.0};
  const Pose2 mount(0.2, -0.1, std::numbers::pi / 2);
  const ScanPoints p = matcher.prepare(scan, mount);
  CHECK(p.beams_total == ranges.size());
  CHECK(p.origin.isApprox(Eigen::Vector2f(0.2f, -0.1f)));
  REQUIRE(p.size() == 4);  // NaN, < range_min, no return, >= range_max, > max_range, 0 dropped
  // Laser beam at -90 deg, 2 m: laser (0, -2) -> base: rotate by 90 deg -> (2, 0) + mount.
  CHECK(p.endpoints[0].x() == Approx(2.2f));
  CHECK(p.endpoints[0].y() == Approx(-0.1f).margin(1e-6));
  CHECK(p.endpoints[1].x() == Approx(0.2f).margin(1e-6));
  CHECK(p.endpoints[1].y() == Approx(0.9f));
  CHECK(p.endpoints[3].x() == Approx(0.2f).margin(1e-6));
  CHECK(p.endpoints[3].y() == Approx(-4.1f));

  ScanMatcherOptions every_other = o;
  every_other.beam_step = 2;
  const ScanPoints q = ScanMatcher(every_other).prepare(scan, mount);
  REQUIRE(q.size() == 2);
  CHECK(q.endpoints[0].isApprox(p.endpoints[0]));
  CHECK(q.endpoints[1].isApprox(p.endpoints[2]));
}

TEST_CASE("degenerate scans give no points and a failed match without crashing", "[scan_matcher]") {
  const Scene scene = roomScene();
  const Laser& laser = scene.laser;
  const OccupancyGrid& grid = scene.grid;
  const ScanMatcher matcher;
  const Pose2 pose = roomMappingPoses()[0];

  const std::vector<float> nans(361, kNaN), far(361, 30.0f), none;
  for (const std::vector<float>* r : {&nans, &far, &none}) {
    const ScanPoints p = matcher.prepare(laser.view(*r), laser.mount);
    CHECK(p.empty());
    CHECK(p.beams_total == r->size());
    CHECK(matcher.score(grid, p, pose) == 0.0);
    CHECK(matcher.logLikelihood(grid, p, pose) == 0.0);
    const MatchResult m = matcher.match(grid, p, pose);
    CHECK_FALSE(m.success);
    CHECK(m.pose.vector() == pose.vector());
    CHECK(m.covariance.allFinite());
    const ProposalFit f = matcher.fitProposal(grid, p, pose, pose, Eigen::Matrix3d::Identity());
    CHECK(std::isfinite(f.log_eta));
    CHECK(f.mean.isFinite());
  }
  // Unusable scan geometry.
  std::mt19937_64 rng(3);
  const std::vector<float> ok = simulate(scene.world, laser, pose, rng);
  RangeScan bad = laser.view(ok);
  bad.angle_increment = kNaN;
  CHECK(matcher.prepare(bad, laser.mount).empty());
  CHECK(matcher.prepare(laser.view(ok), Pose2(kNaN, 0, 0)).empty());
  // Non-finite initial pose: failed match, no exception.
  const ScanPoints p = matcher.prepare(laser.view(ok), laser.mount);
  CHECK_FALSE(matcher.match(grid, p, Pose2(kNaN, 0, 0)).success);
}

TEST_CASE("score is continuous in translation and zero beyond the kernel", "[scan_matcher]") {
  FakeGrid grid(0.05);
  grid.set(20, 20, 2.0f);  // one obstacle cell, centre (1.025, 1.025)
  const ScanMatcher matcher;
  // One beam from the far left, endpoint swept across three cells in 0.1 mm steps: the window
  // around the endpoint jumps by a cell at each boundary, the clamped score must not.
  const ScanPoints beam = onePoint({-5.0f, 1.025f}, {0.0f, 0.0f});
  double previous = matcher.score(grid, beam, Pose2(0.95, 1.03, 0.0));
  double peak = previous, max_jump = 0.0;
  for (int i = 1; i <= 1500; ++i) {
    const double s = matcher.score(grid, beam, Pose2(0.95 + i * 1e-4, 1.03, 0.0));
    max_jump = std::max(max_jump, std::abs(s - previous));
    peak = std::max(peak, s);
    previous = s;
  }
  CHECK(peak > 0.99);
  CHECK(max_jump < 0.005);
  // Outside R = 1.5 cells: nothing matched, score 0, the fixed likelihood penalty.
  int matched = -1;
  CHECK(matcher.score(grid, beam, Pose2(1.025 + 0.076, 1.025, 0.0)) == 0.0);
  const double ll = matcher.logLikelihood(grid, beam, Pose2(1.025 + 0.08, 1.025, 0.0), &matched);
  CHECK(matched == 0);
  CHECK(ll == Approx(-0.075 * 0.075 / (2 * 0.075 * 0.075) / 3.0).epsilon(1e-5));
  CHECK(matcher.logLikelihood(grid, beam, Pose2(1.025, 1.025, 0.0), &matched) ==
        Approx(0.0).margin(1e-9));
  CHECK(matched == 1);
}

TEST_CASE("an unmatched beam costs as much as one whose obstacle lies no_hit_distance away",
          "[scan_matcher]") {
  FakeGrid grid(0.05);
  grid.set(20, 20, 2.0f);  // one obstacle cell, centre (1.025, 1.025)
  const ScanPoints beam = onePoint({-5.0f, 1.025f}, {0.0f, 0.0f});
  const Pose2 on(1.025, 1.025, 0.0), off(1.025 + 0.08, 1.025, 0.0);  // off: d > R = 0.075
  const double two_var_gain = 2 * 0.075 * 0.075 * 3.0;
  ScanMatcherOptions o;
  o.no_hit_distance = 0.5;
  const ScanMatcher far(o);
  o.no_hit_distance = 0.05;  // below R: R applies, as by default
  const ScanMatcher near(o);
  CHECK(far.logLikelihood(grid, beam, off) == Approx(-0.5 * 0.5 / two_var_gain).epsilon(1e-5));
  CHECK(near.logLikelihood(grid, beam, off) == Approx(-0.075 * 0.075 / two_var_gain).epsilon(1e-5));
  CHECK(far.logLikelihood(grid, beam, on) == Approx(0.0).margin(1e-9));  // matched: unchanged
  CHECK(far.score(grid, beam, off) == 0.0);

  // A whole scan, on both evaluation paths (cell by cell and occupancy rows): every unmatched
  // beam costs (D² − R²)/(2σ²·gain) more, matched beams the same, so a pose half a metre off
  // loses far more likelihood against the true one.
  const World world = room();
  const Laser laser;
  const OccupancyGrid cells = mapOf(world, laser, roomMappingPoses());
  const TiledGrid tiles = mapOf(world, laser, roomMappingPoses(), 1, TiledGrid());
  const ScanMatcher plain;
  std::mt19937_64 rng(3);
  const Pose2 truth = roomMappingPoses()[1];
  const ScanPoints p = plain.prepare(laser.view(simulate(world, laser, truth, rng)), laser.mount);
  REQUIRE(p.size() > 100);
  const Pose2 shifted(truth.x + 0.5, truth.y - 0.2, truth.theta + 0.1);
  const double extra = (0.5 * 0.5 - 0.075 * 0.075) / two_var_gain;
  for (const Pose2& at : {truth, shifted}) {
    int matched = 0;
    const double ll_cells = plain.logLikelihood(cells, p, at, &matched);
    const double unmatched = static_cast<double>(p.size()) - matched;
    CHECK(far.logLikelihood(cells, p, at) == Approx(ll_cells - unmatched * extra).epsilon(1e-9));
    int matched_tiles = 0;
    const double ll_tiles = plain.logLikelihood(tiles, p, at, &matched_tiles);
    CHECK(matched_tiles == matched);
    CHECK(far.logLikelihood(tiles, p, at) == Approx(ll_tiles - unmatched * extra).epsilon(1e-9));
  }
  const double gap_plain =
      plain.logLikelihood(cells, p, truth) - plain.logLikelihood(cells, p, shifted);
  const double gap_far = far.logLikelihood(cells, p, truth) - far.logLikelihood(cells, p, shifted);
  INFO("log-likelihood gap truth vs 0.5 m off: " << gap_plain << " plain, " << gap_far
                                                 << " with no_hit_distance 0.5 m");
  CHECK(gap_far > 10 * gap_plain);
}

TEST_CASE("free check rejects obstacles seen through an occupied cell", "[scan_matcher]") {
  FakeGrid grid(0.05);
  for (int x = 10; x <= 12; ++x)  // a wall three cells thick: x in [0.5, 0.65)
    for (int y = 0; y < 40; ++y) grid.set(x, y, 2.0f);
  const Pose2 at(0.0, 0.0, 0.0);
  const ScanMatcher with_check;
  ScanMatcherOptions o;
  o.free_check_offset = -1.0;
  const ScanMatcher without_check(o);
  // Endpoint inside the wall near the centre of its last column, beam coming from the left:
  // the only nearby occupied cells have occupied cells in front of them along the beam.
  const ScanPoints from_left = onePoint({0.0f, 1.025f}, {0.624f, 1.025f});
  CHECK(without_check.score(grid, from_left, at) > 0.9);
  CHECK(with_check.score(grid, from_left, at) == 0.0);
  // The same endpoint reached from the right sees the wall face first: it matches.
  const ScanPoints from_right = onePoint({2.0f, 1.025f}, {0.624f, 1.025f});
  CHECK(with_check.score(grid, from_right, at) > 0.9);
}

TEST_CASE("score and likelihood are highest at the true pose", "[scan_matcher]") {
  const Scene scene = roomScene();
  const OccupancyGrid& grid = scene.grid;
  const ScanMatcher matcher;
  std::mt19937_64 rng(7);
  const Pose2 truth = kRoomPose * Pose2(4.0, 3.8, 0.4);
  const ScanPoints p = scene.scan(matcher, truth, rng);
  REQUIRE(p.size() > 300);
  const double at_truth = matcher.score(grid, p, truth);
  const double ll_truth = matcher.logLikelihood(grid, p, truth);
  CHECK(at_truth > 0.5 * static_cast<double>(p.size()));
  for (const Pose2& d : {Pose2(0.03, 0, 0), Pose2(0, -0.03, 0), Pose2(0, 0, 1 * kDeg),
                         Pose2(0.1, 0.1, 0), Pose2(-0.2, 0.05, 3 * kDeg)}) {
    const Pose2 off(truth.x + d.x, truth.y + d.y, truth.theta + d.theta);
    CHECK(matcher.score(grid, p, off) < at_truth);
    CHECK(matcher.logLikelihood(grid, p, off) < ll_truth);
  }
}

TEST_CASE("match recovers offset poses in a structured room", "[scan_matcher]") {
  const Scene scene = roomScene();
  const OccupancyGrid& grid = scene.grid;
  std::mt19937_64 rng(11);
  const std::vector<Pose2> truths = {kRoomPose * Pose2(4.0, 3.8, 0.4),
                                     kRoomPose * Pose2(6.5, 3.5, -2.0),
                                     kRoomPose * Pose2(2.5, 5.0, 1.5)};

  SECTION("odometry-sized offsets with default options") {
    const ScanMatcher matcher;
    for (const Pose2& truth : truths) {
      const ScanPoints p = scene.scan(matcher, truth, rng);
      for (const Pose2& d : {Pose2(0.05, -0.04, 2 * kDeg), Pose2(-0.06, 0.03, -3 * kDeg),
                             Pose2(0.0, 0.07, 1 * kDeg)}) {
        const Pose2 initial(truth.x + d.x, truth.y + d.y, truth.theta + d.theta);
        const MatchResult m = matcher.match(grid, p, initial);
        CHECK(m.success);
        CHECK(translationError(m.pose, truth) < 0.015);
        CHECK(std::abs(angleDiff(m.pose.theta, truth.theta)) < 0.5 * kDeg);
        CHECK(m.score > matcher.score(grid, p, initial));
        CHECK(m.evaluations <= 200);
      }
    }
  }

  SECTION("larger offsets with a wider kernel") {
    ScanMatcherOptions o;
    o.kernel_radius = 6;
    o.sigma = 0.1;
    o.max_iterations = 400;
    const ScanMatcher matcher(o);
    for (const Pose2& truth : truths) {
      const ScanPoints p = scene.scan(matcher, truth, rng);
      for (const Pose2& d :
           {Pose2(0.15, -0.1, 4 * kDeg), Pose2(-0.2, 0.0, -5 * kDeg), Pose2(0.1, 0.15, 3 * kDeg)}) {
        const Pose2 initial(truth.x + d.x, truth.y + d.y, truth.theta + d.theta);
        const MatchResult m = matcher.match(grid, p, initial);
        CHECK(m.success);
        CHECK(translationError(m.pose, truth) < 0.02);
        CHECK(std::abs(angleDiff(m.pose.theta, truth.theta)) < 0.5 * kDeg);
      }
    }
  }
}

TEST_CASE("match works on any grid type with the same interface", "[scan_matcher]") {
  FakeGrid grid(0.05);
  for (int i = 5; i < 60; ++i) {  // an L of walls: x = 0.25..0.3 and y = 0.25..0.3
    grid.set(5, i, 2.0f);
    grid.set(i, 5, 2.0f);
  }
  // Points on both walls, on cell centres, seen from (1.5, 1.5).
  ScanPoints p;
  p.origin = Eigen::Vector2f::Zero();
  for (int i = 0; i < 40; ++i) {
    p.endpoints.emplace_back(0.275f - 1.5f, 0.425f + 0.05f * static_cast<float>(i) - 1.5f);
    p.endpoints.emplace_back(0.425f + 0.05f * static_cast<float>(i) - 1.5f, 0.275f - 1.5f);
  }
  p.beams_total = p.endpoints.size();
  const ScanMatcher matcher;
  const MatchResult m = matcher.match(grid, p, Pose2(1.53, 1.47, 0.01));
  CHECK(m.success);
  CHECK(translationError(m.pose, Pose2(1.5, 1.5, 0.0)) < 0.005);
  CHECK(std::abs(m.pose.theta) < 0.2 * kDeg);
}

TEST_CASE("match fails on an empty grid", "[scan_matcher]") {
  const Scene scene = roomScene();
  const OccupancyGrid empty;
  const ScanMatcher matcher;
  std::mt19937_64 rng(5);
  const ScanPoints p = scene.scan(matcher, roomMappingPoses()[1], rng);
  REQUIRE_FALSE(p.empty());
  const MatchResult m = matcher.match(empty, p, roomMappingPoses()[1]);
  CHECK_FALSE(m.success);
  CHECK(m.score == 0.0);
  CHECK(m.matched_beams == 0);
  CHECK(m.log_likelihood < 0.0);
}

TEST_CASE("match covariance is large along a featureless corridor", "[scan_matcher]") {
  // A 2 m wide corridor, 100 m long (ends out of range), along a direction 0.4 rad off the
  // grid axes so its walls are staircases of cells.
  const double axis_angle = 0.4;
  const Pose2 frame(0.0, 0.0, axis_angle);
  const World corridor = {{frame * Eigen::Vector2d(-50, -1), frame * Eigen::Vector2d(50, -1)},
                          {frame * Eigen::Vector2d(-50, 1), frame * Eigen::Vector2d(50, 1)}};
  std::vector<Pose2> poses;
  for (double x = -4.0; x <= 4.0; x += 1.0) poses.push_back(frame * Pose2(x, 0.1 * x / 4, 0.05));
  const Scene scene(corridor, poses);
  const ScanMatcher matcher;
  std::mt19937_64 rng(9);
  const Pose2 truth = frame * Pose2(0.5, -0.2, -0.1);
  const ScanPoints p = scene.scan(matcher, truth, rng);
  const MatchResult m = matcher.match(scene.grid, p, frame * Pose2(0.5, -0.15, -0.1 + 2 * kDeg));
  CHECK(m.success);
  // Across the corridor and in heading the scan pins the pose down.
  const Eigen::Vector2d along(std::cos(axis_angle), std::sin(axis_angle));
  const Eigen::Vector2d across(-along.y(), along.x());
  CHECK(std::abs((m.pose.translation() - truth.translation()).dot(across)) < 0.015);
  CHECK(std::abs(angleDiff(m.pose.theta, truth.theta)) < 0.5 * kDeg);
  // Along the axis only the cell-centre texture constrains the fit (see MatchResult).
  const Eigen::Matrix2d cxy = m.covariance.topLeftCorner<2, 2>();
  const double var_along = along.dot(cxy * along), var_across = across.dot(cxy * across);
  CHECK(var_along > 20.0 * var_across);
  CHECK(std::sqrt(var_along) > 0.05);
  CHECK(std::sqrt(var_across) < 0.02);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(m.covariance);
  CHECK(eig.eigenvalues().minCoeff() > 0.0);

  // In the structured room the same covariance is small in every direction.
  const Scene room_scene = roomScene();
  const Pose2 room_truth = kRoomPose * Pose2(4.0, 3.8, 0.4);
  const ScanPoints q = room_scene.scan(matcher, room_truth, rng);
  const MatchResult mr = matcher.match(room_scene.grid, q, room_truth);
  const Eigen::Matrix2d rc = mr.covariance.topLeftCorner<2, 2>();
  const double largest = 0.5 * (rc(0, 0) + rc(1, 1)) +
                         std::hypot(0.5 * (rc(0, 0) - rc(1, 1)), rc(0, 1));  // 2x2 eigenvalue
  CHECK(std::sqrt(largest) < 0.025);
}

TEST_CASE("fitProposal balances the scan likelihood against the motion prior", "[scan_matcher]") {
  const Scene scene = roomScene();
  const OccupancyGrid& grid = scene.grid;
  const ScanMatcher matcher;
  std::mt19937_64 rng(13);
  const Pose2 truth = kRoomPose * Pose2(4.0, 3.8, 0.4);
  const ScanPoints p = scene.scan(matcher, truth, rng);
  const MatchResult m = matcher.match(grid, p, Pose2(truth.x + 0.04, truth.y, truth.theta));
  REQUIRE(m.success);
  const Pose2 mode = m.pose;

  SECTION("a broad prior leaves the mean at the mode") {
    const Eigen::Matrix3d broad = Eigen::Vector3d(1.0, 1.0, 0.5).asDiagonal();
    const ProposalFit f =
        matcher.fitProposal(grid, p, mode, Pose2(mode.x + 0.1, mode.y, mode.theta), broad);
    CHECK(f.samples == 27);
    CHECK(translationError(f.mean, mode) < 0.005);
    CHECK(std::abs(angleDiff(f.mean.theta, mode.theta)) < 0.002);
    CHECK(std::isfinite(f.log_eta));
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(f.covariance);
    CHECK(eig.eigenvalues().minCoeff() > 0.0);
    CHECK(f.covariance(0, 0) < 0.02 * 0.02);
  }

  SECTION("a tight prior pulls the mean toward the prior") {
    const Eigen::Matrix3d tight = Eigen::Vector3d(1e-4, 1e-4, 1e-5).asDiagonal();
    const Pose2 prior(mode.x + 0.02, mode.y - 0.02, mode.theta + 0.01);
    const ProposalFit f = matcher.fitProposal(grid, p, mode, prior, tight);
    CHECK(f.mean.x - mode.x > 0.005);
    CHECK(f.mean.y - mode.y < -0.005);
    CHECK(angleDiff(f.mean.theta, mode.theta) > 0.002);
    CHECK(translationError(f.mean, prior) < translationError(mode, prior));
  }

  SECTION("log_eta is the log of the summed sample weights") {
    const Eigen::Matrix3d cov = Eigen::Vector3d(0.01, 0.02, 0.005).asDiagonal();
    const Pose2 prior(mode.x - 0.03, mode.y + 0.01, mode.theta - 0.02);
    const ProposalFit f = matcher.fitProposal(grid, p, mode, prior, cov);
    double sum = 0.0;
    const Eigen::Matrix3d info = cov.inverse();
    for (int i = -1; i <= 1; ++i)
      for (int j = -1; j <= 1; ++j)
        for (int k = -1; k <= 1; ++k) {
          const Pose2 x(mode.x + 0.02 * i, mode.y + 0.02 * j, mode.theta + 0.01 * k);
          const Eigen::Vector3d d(x.x - prior.x, x.y - prior.y, angleDiff(x.theta, prior.theta));
          const double prior_density =
              std::exp(-0.5 * d.dot(info * d)) /
              std::sqrt(std::pow(2 * std::numbers::pi, 3) * cov.determinant());
          // Scale the likelihood by a constant to stay in double range; log_eta shifts by it.
          sum += std::exp(matcher.logLikelihood(grid, p, x) - m.log_likelihood) * prior_density;
        }
    CHECK(f.log_eta == Approx(m.log_likelihood + std::log(sum)).epsilon(1e-9));
  }

  SECTION("angles wrap across pi") {
    const Pose2 near_pi(mode.x, mode.y, std::numbers::pi - 0.004);
    const Pose2 prior(mode.x, mode.y, -std::numbers::pi + 0.004);  // 0.008 rad away across the cut
    const Eigen::Matrix3d tight = Eigen::Vector3d(1e-4, 1e-4, 1e-6).asDiagonal();
    const ProposalFit f = matcher.fitProposal(grid, p, near_pi, prior, tight);
    CHECK(std::abs(angleDiff(f.mean.theta, prior.theta)) < 0.006);
    CHECK(f.covariance(2, 2) < 0.01 * 0.01);
  }

  SECTION("very bad poses keep log_eta finite and low") {
    const Eigen::Matrix3d tight = Eigen::Vector3d(1e-6, 1e-6, 1e-8).asDiagonal();
    const ProposalFit good = matcher.fitProposal(grid, p, mode, mode, tight);
    const Pose2 far(mode.x + 40.0, mode.y - 25.0, mode.theta + 2.0);
    const ProposalFit bad = matcher.fitProposal(grid, p, far, mode, tight);
    CHECK(std::isfinite(bad.log_eta));
    CHECK(bad.log_eta < good.log_eta - 1e6);
    CHECK(bad.mean.isFinite());
    CHECK(bad.covariance.allFinite());
    // A zero motion covariance (robot standing still) is still a valid prior.
    const ProposalFit still = matcher.fitProposal(grid, p, mode, mode, Eigen::Matrix3d::Zero());
    CHECK(std::isfinite(still.log_eta));
    CHECK(translationError(still.mean, mode) < 1e-3);
  }

  SECTION("invalid priors are rejected") {
    Eigen::Matrix3d negative = Eigen::Matrix3d::Identity();
    negative(1, 1) = -1.0;
    CHECK_THROWS_AS(matcher.fitProposal(grid, p, mode, mode, negative), std::invalid_argument);
    CHECK_THROWS_AS(
        matcher.fitProposal(grid, p, mode, Pose2(kNaN, 0, 0), Eigen::Matrix3d::Identity()),
        std::invalid_argument);
  }
}

// ---- hit points ----

namespace {
/// FakeGrid plus per-cell hit points and a switch, like a TiledGrid with track_hit_points.
class FakeHitGrid : public FakeGrid {
 public:
  FakeHitGrid(double res, bool tracks) : FakeGrid(res), tracks_(tracks) {}
  bool tracksHitPoints() const { return tracks_; }
  Eigen::Vector2d hitPoint(const Eigen::Vector2i& c) const {
    const auto it = hits_.find({c.x(), c.y()});
    return tracks_ && it != hits_.end() ? it->second : cellCenter(c);
  }
  void setHit(int x, int y, const Eigen::Vector2d& p) { hits_[{x, y}] = p; }

 private:
  bool tracks_;
  std::map<std::pair<int, int>, Eigen::Vector2d> hits_;
};

/// Walls that do not sit on cell boundaries: an axis-aligned room with walls at odd
/// millimetres and two boxes, so cell centres are off the walls by up to half a cell.
World offsetRoom() {
  World w;
  addPolygon(w, {{-3.033, -2.511}, {2.017, -2.511}, {2.017, 1.529}, {-3.033, 1.529}});
  addPolygon(w, box({0.513, -0.987, 0.0}, 0.61, 0.43));
  addPolygon(w, box({-1.71, 0.62, 0.7}, 0.5, 0.8));
  return w;
}

/// Mean translation and heading error of match() over a set of truths and initial offsets.
struct MatchErrors {
  double translation = 0, heading = 0;
  int failures = 0;
};

template <class Grid>
MatchErrors matchErrors(const Grid& grid, const World& world, const Laser& laser,
                        const std::vector<Pose2>& truths) {
  const ScanMatcher matcher;
  std::mt19937_64 rng(17);  // the same scans for every grid
  MatchErrors e;
  int n = 0;
  for (const Pose2& truth : truths) {
    const ScanPoints p =
        matcher.prepare(laser.view(simulate(world, laser, truth, rng)), laser.mount);
    for (const Pose2& d : {Pose2(0.05, -0.04, 2 * kDeg), Pose2(-0.06, 0.03, -3 * kDeg),
                           Pose2(0.0, 0.07, 1 * kDeg), Pose2(0.03, 0.03, 0.0)}) {
      const MatchResult m =
          matcher.match(grid, p, Pose2(truth.x + d.x, truth.y + d.y, truth.theta + d.theta));
      e.failures += !m.success;
      e.translation += translationError(m.pose, truth);
      e.heading += std::abs(angleDiff(m.pose.theta, truth.theta));
      ++n;
    }
  }
  e.translation /= n;
  e.heading /= n;
  return e;
}
}  // namespace

TEST_CASE("score measures distances to hit points when the grid tracks them", "[scan_matcher]") {
  // Random occupied cells with random hit points; the matcher's d must be the exact distance
  // to the nearest candidate hit point in the window (clamped to R), whatever order the
  // kernel walk and its early stop visit cells in.
  const double res = 0.05;
  FakeHitGrid tracked(res, true), untracked(res, false);
  std::mt19937_64 rng(23);
  std::uniform_int_distribution<int> cell(10, 30);
  std::uniform_real_distribution<double> inside(-0.499, 0.499), unit(0.0, 1.0);
  std::vector<std::pair<int, int>> occupied;
  for (int k = 0; k < 120; ++k) {
    const int x = cell(rng), y = cell(rng);
    const Eigen::Vector2d hp =
        tracked.cellCenter({x, y}) + res * Eigen::Vector2d(inside(rng), inside(rng));
    for (FakeHitGrid* g : {&tracked, &untracked}) {
      g->set(x, y, 1.0f);
      g->setHit(x, y, hp);
    }
    occupied.push_back({x, y});
  }
  ScanPoints p;
  for (int k = 0; k < 400; ++k)
    p.endpoints.emplace_back(static_cast<float>((12 + 17 * unit(rng)) * res),
                             static_cast<float>((12 + 17 * unit(rng)) * res));
  p.beams_total = p.endpoints.size();

  for (int radius : {0, 1, 2, 4}) {
    ScanMatcherOptions o;
    o.kernel_radius = radius;
    o.free_check_offset = -1.0;  // every occupied cell is a candidate
    const ScanMatcher matcher(o);
    const double big_r = (radius + 0.5) * res;
    double expected_tracked = 0.0, expected_centres = 0.0, ll_tracked = 0.0;
    const double floor = std::exp(-big_r * big_r / (2 * o.sigma * o.sigma));
    auto kernel = [&](double d2) {
      return (std::exp(-d2 / (2 * o.sigma * o.sigma)) - floor) / (1 - floor);
    };
    for (const Eigen::Vector2f& ef : p.endpoints) {
      const Eigen::Vector2d e = ef.cast<double>();
      const Eigen::Vector2i c = tracked.worldToCell(e);
      double best_hit = big_r * big_r, best_centre = big_r * big_r;
      for (const auto& [x, y] : occupied) {
        if (std::abs(x - c.x()) > radius || std::abs(y - c.y()) > radius) continue;
        best_hit = std::min(best_hit, (tracked.hitPoint({x, y}) - e).squaredNorm());
        best_centre = std::min(best_centre, (tracked.cellCenter({x, y}) - e).squaredNorm());
      }
      expected_tracked += kernel(best_hit);
      expected_centres += kernel(best_centre);
      ll_tracked += -best_hit / (2 * o.likelihood_sigma * o.likelihood_sigma * o.likelihood_gain);
    }
    INFO("kernel radius " << radius);
    CHECK(matcher.score(tracked, p, Pose2()) == Approx(expected_tracked).epsilon(1e-4));
    CHECK(matcher.logLikelihood(tracked, p, Pose2()) == Approx(ll_tracked).epsilon(1e-4));
    // Not tracking: cell centres, exactly as on a grid without hit points.
    CHECK(matcher.score(untracked, p, Pose2()) == Approx(expected_centres).epsilon(1e-4));
    CHECK(matcher.score(untracked, p, Pose2()) ==
          matcher.score(static_cast<const FakeGrid&>(untracked), p, Pose2()));
    CHECK(expected_tracked != Approx(expected_centres).epsilon(1e-3));
  }
}

TEST_CASE("match on a grid tracking hit points is more precise off cell boundaries",
          "[scan_matcher]") {
  const Laser laser;
  TiledGrid::Options tracked_options;
  tracked_options.track_hit_points = true;

  struct Case {
    const char* name;
    World world;
    std::vector<Pose2> mapping, truths;
  };
  const std::vector<Case> cases = {
      {"walls at odd millimetres",
       offsetRoom(),
       {Pose2(-2.0, -1.5, 0.3), Pose2(1.0, 0.8, -2.5), Pose2(-0.5, -2.0, 1.2),
        Pose2(1.2, -1.8, 2.2), Pose2(-2.5, 1.0, -0.6), Pose2(0.0, 1.0, -1.4)},
       {Pose2(-0.8, -0.3, 0.2), Pose2(1.3, 0.2, 2.8), Pose2(-2.3, -1.7, -1.0)}},
      {"rotated room",
       room(),
       roomMappingPoses(),
       {kRoomPose * Pose2(4.0, 3.8, 0.4), kRoomPose * Pose2(6.5, 3.5, -2.0),
        kRoomPose * Pose2(2.5, 5.0, 1.5)}},
  };
  for (const Case& c : cases) {
    const TiledGrid untracked = mapOf<TiledGrid>(c.world, laser, c.mapping);
    const TiledGrid tracked =
        mapOf<TiledGrid>(c.world, laser, c.mapping, 1, TiledGrid(tracked_options));
    const MatchErrors centres = matchErrors(untracked, c.world, laser, c.truths);
    const MatchErrors hits = matchErrors(tracked, c.world, laser, c.truths);
    INFO(c.name << ": mean translation error " << centres.translation * 1000 << " mm on cell "
                << "centres, " << hits.translation * 1000 << " mm on hit points; heading "
                << centres.heading / kDeg << " / " << hits.heading / kDeg << " deg");
    CHECK(centres.failures == 0);
    CHECK(hits.failures == 0);
    CHECK(hits.translation < 0.7 * centres.translation);
    CHECK(hits.translation < 0.005);
  }
}

namespace {
/// A TiledGrid read one cell at a time: it forwards everything the matcher uses except
/// occupancyRows(), so the matcher takes its cell-by-cell kernel walk, the reference for the
/// occupancy-row path.
class CellByCell {
 public:
  explicit CellByCell(const TiledGrid& g) : g_(g) {}
  double resolution() const { return g_.resolution(); }
  Eigen::Vector2i worldToCell(const Eigen::Vector2d& p) const { return g_.worldToCell(p); }
  Eigen::Vector2d cellCenter(const Eigen::Vector2i& c) const { return g_.cellCenter(c); }
  float logOdds(const Eigen::Vector2i& c) const { return g_.logOdds(c); }
  bool tracksHitPoints() const { return g_.tracksHitPoints(); }
  Eigen::Vector2d hitPoint(const Eigen::Vector2i& c) const { return g_.hitPoint(c); }

 private:
  const TiledGrid& g_;
};

/// Poses around the room's mapping poses, some far enough off that many beams miss the map or
/// fall outside it.
std::vector<Pose2> posesAround(const std::vector<Pose2>& centres, int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> xy(0.0, 0.2), th(0.0, 0.1);
  std::vector<Pose2> poses;
  for (int k = 0; k < n; ++k) {
    const Pose2& c = centres[static_cast<std::size_t>(k) % centres.size()];
    const double scale = k % 5 == 4 ? 10.0 : 1.0;
    poses.emplace_back(c.x + scale * xy(rng), c.y + scale * xy(rng), c.theta + th(rng));
  }
  return poses;
}

/// Score, log-likelihood and matched beams on `grid` equal the cell-by-cell walk's, exactly;
/// returns how many poses matched at least one beam (so callers can tell the test was not
/// vacuous).
int requireSameAsWalk(const ScanMatcher& m, const TiledGrid& grid, const ScanPoints& points,
                      const std::vector<Pose2>& poses) {
  const CellByCell walk(grid);
  int with_matches = 0;
  for (const Pose2& pose : poses) {
    INFO("pose " << pose.x << " " << pose.y << " " << pose.theta);
    REQUIRE(m.score(grid, points, pose) == m.score(walk, points, pose));
    int matched = -1, matched_walk = -2;
    REQUIRE(m.logLikelihood(grid, points, pose, &matched) ==
            m.logLikelihood(walk, points, pose, &matched_walk));
    REQUIRE(matched == matched_walk);
    if (matched > 0) ++with_matches;
  }
  return with_matches;
}
}  // namespace

TEST_CASE("scores on a tiled grid equal the cell-by-cell kernel walk",
          "[scan_matcher][occupancy_rows]") {
  const World world = room();
  const Laser laser;
  const bool hit_points = GENERATE(false, true);
  TiledGrid::Options go;
  go.track_hit_points = hit_points;
  const TiledGrid grid = mapOf(world, laser, roomMappingPoses(), 3, TiledGrid(go));
  std::mt19937_64 rng(5);
  const std::vector<Pose2> truths = roomMappingPoses();
  // Radius 15 is past kMaxBitRadius and a 0.1 m offset (2 cells) past the neighbour free
  // check: both take the walk on both grids, and must agree too.
  for (int radius : {0, 1, 2, 4, 14, 15})
    for (double free_offset : {-1.0, 0.0, 0.06, 0.1})
      for (float threshold : {0.0f, 0.4f, -0.3f}) {
        ScanMatcherOptions o;
        o.kernel_radius = radius;
        o.free_check_offset = free_offset;
        o.occupied_threshold = threshold;
        o.beam_step = radius > 4 ? 7 : 2;
        const ScanMatcher m(o);
        const ScanPoints points = m.prepare(
            laser.view(simulate(world, laser, truths[static_cast<std::size_t>(radius) % 8], rng)),
            laser.mount);
        INFO("hit points " << hit_points << ", radius " << radius << ", free check offset "
                           << free_offset << ", threshold " << threshold);
        const int n = radius > 4 ? 6 : 20;
        CHECK(requireSameAsWalk(m, grid, points, posesAround(truths, n, 7)) > 0);
      }
}

TEST_CASE("tiled grid scores stay equal to the walk after map updates and copy-on-write copies",
          "[scan_matcher][occupancy_rows]") {
  const World world = room();
  const Laser laser;
  const std::vector<Pose2> truths = roomMappingPoses();
  // Half the mapping poses first: the rest add cells later, where caches are already filled.
  const std::vector<Pose2> first(truths.begin(), truths.begin() + 4);
  const std::vector<Pose2> later(truths.begin() + 4, truths.end());
  TiledGrid grid = mapOf(world, laser, first, 11, TiledGrid());
  const ScanMatcher m;
  std::mt19937_64 rng(13);
  const ScanPoints points =
      m.prepare(laser.view(simulate(world, laser, truths[5], rng)), laser.mount);
  const std::vector<Pose2> poses = posesAround({truths[5]}, 15, 17);
  requireSameAsWalk(m, grid, points, poses);  // fills the caches of the tiles it reads
  const double before = m.score(grid, points, truths[5]);

  SECTION("scans added to the grid itself") {
    grid = mapOf(world, laser, later, 12, std::move(grid));
    CHECK(m.score(grid, points, truths[5]) != before);  // the update changed what is read
    CHECK(requireSameAsWalk(m, grid, points, poses) > 0);
  }
  SECTION("scans added to a copy leave the original's scores alone") {
    TiledGrid copy = mapOf(world, laser, later, 12, TiledGrid(grid));
    CHECK(m.score(copy, points, truths[5]) != before);
    CHECK(requireSameAsWalk(m, copy, points, poses) > 0);
    CHECK(m.score(grid, points, truths[5]) == before);
    CHECK(requireSameAsWalk(m, grid, points, poses) > 0);
  }
  SECTION("matching and the proposal fit agree with the walk") {
    const CellByCell walk(grid);
    const Pose2 start(truths[5].x + 0.08, truths[5].y - 0.05, truths[5].theta + 0.03);
    const MatchResult a = m.match(grid, points, start), b = m.match(walk, points, start);
    CHECK(a.success);
    CHECK(a.pose.x == b.pose.x);
    CHECK(a.pose.y == b.pose.y);
    CHECK(a.pose.theta == b.pose.theta);
    CHECK(a.score == b.score);
    CHECK(a.evaluations == b.evaluations);
    const Eigen::Matrix3d prior = Eigen::Vector3d(0.01, 0.01, 0.003).asDiagonal();
    const ProposalFit fa = m.fitProposal(grid, points, a.pose, start, prior);
    const ProposalFit fb = m.fitProposal(walk, points, b.pose, start, prior);
    CHECK(fa.log_eta == fb.log_eta);
    CHECK(fa.mean.x == fb.mean.x);
  }
}

TEST_CASE("a wall in the neighbouring tile is seen from a tile whose bits are cached",
          "[scan_matcher][occupancy_rows]") {
  // Cell x = 32 opens tile 1; an endpoint in cell 31 (tile 0) has it in its window.
  TiledGrid grid;
  const double res = grid.resolution();
  const Eigen::Vector2i wall(TiledGrid::kTileSide, 7);
  const Eigen::Vector2d wall_centre = grid.cellCenter(wall);
  // Make tile 0 exist and cache its bits: a few free cells around the endpoint's cell.
  const std::vector<float> short_range{0.2f};
  const RangeScan short_beam{short_range, 0.0, 0.0, 0.05, 8.0};
  grid.insertScan(short_beam, Pose2(wall_centre.x() - 0.45, wall_centre.y(), 0.0));
  ScanMatcherOptions o;
  o.free_check_offset = -1.0;
  const ScanMatcher m(o);
  // One endpoint at the centre of cell 31, robot at the map origin.
  const ScanPoints p =
      onePoint(Eigen::Vector2f::Zero(), Eigen::Vector2f(static_cast<float>(wall_centre.x() - res),
                                                        static_cast<float>(wall_centre.y())));
  CHECK(m.score(grid, p, Pose2()) == 0.0);  // fills tile 0's cache: nothing occupied yet
  // Now the wall appears, written by a ray that stays in tile 1 (looking along −x).
  const std::vector<float> range{0.3f};
  const RangeScan beam{range, 0.0, 0.0, 0.05, 8.0};
  for (int k = 0; k < 3; ++k)
    grid.insertScan(beam, Pose2(wall_centre.x() + 0.3, wall_centre.y(), std::numbers::pi));
  REQUIRE(grid.logOdds(wall) > 0.0f);
  const double expected = m.score(CellByCell(grid), p, Pose2());
  CHECK(expected > 0.0);  // one cell away: within the radius-1 window
  CHECK(m.score(grid, p, Pose2()) == expected);
}

TEST_CASE("endpoint cells of several poses equal the scalar floor arithmetic", "[scan_matcher]") {
  // detail::endpointCells takes two poses at a time on SSE2 and replaces std::floor: every
  // cell and offset must still be what floor(q + 1/2) gives, including negative cells and
  // endpoints exactly on a rounding boundary.
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> xy(-60.0, 60.0), th(-std::numbers::pi, std::numbers::pi),
      e(-30.0, 30.0);
  std::uniform_int_distribution<int> boundary(-1000, 1000);
  const double res = 0.05;
  const Eigen::Vector2d centre0(0.5 * res, 0.5 * res);
  int on_boundary = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const int n = 1 + trial % 7;  // odd and even counts
    double x[8], y[8], c[8], s[8];
    for (int k = 0; k < 8; ++k) {
      const double theta = trial % 3 == 0 ? 0.0 : th(rng);
      x[k] = xy(rng);
      y[k] = xy(rng);
      c[k] = std::cos(theta);
      s[k] = std::sin(theta);
    }
    double ex = e(rng), ey = e(rng);
    if (trial % 3 == 0) {
      // Heading 0: put the endpoint of pose 0 on a cell boundary (q + 1/2 an integer).
      ex = (boundary(rng) - 0.5) * res + centre0.x() - x[0];
      ey = (boundary(rng) - 0.5) * res + centre0.y() - y[0];
    }
    int cell_x[8], cell_y[8];
    float ux[8], uy[8];
    tessera::scan_matching::detail::endpointCells(n, x, y, c, s, ex, ey, centre0, res, cell_x,
                                                  cell_y, ux, uy);
    for (int k = 0; k < n; ++k) {
      const double px = x[k] + c[k] * ex - s[k] * ey, py = y[k] + s[k] * ex + c[k] * ey;
      const double qx = (px - centre0.x()) * (1.0 / res), qy = (py - centre0.y()) * (1.0 / res);
      const double fx = std::floor(qx + 0.5), fy = std::floor(qy + 0.5);
      if (fx == qx + 0.5 || fy == qy + 0.5) ++on_boundary;
      INFO("trial " << trial << " pose " << k);
      REQUIRE(cell_x[k] == static_cast<int>(fx));
      REQUIRE(cell_y[k] == static_cast<int>(fy));
      REQUIRE(ux[k] == static_cast<float>((qx - fx) * res));
      REQUIRE(uy[k] == static_cast<float>((qy - fy) * res));
    }
  }
  CHECK(on_boundary > 100);
}

namespace {
/// The hill climbing of ScanMatcher::match() written out plainly, one score() call per move and
/// only the move back skipped: match() must land on the same pose, score and evaluation count.
MatchResult plainHillClimb(const ScanMatcher& m, const TiledGrid& grid, const ScanPoints& points,
                           const Pose2& initial) {
  const ScanMatcherOptions& o = m.options();
  MatchResult r;
  Pose2 pose = initial;
  double best = m.score(grid, points, pose);
  int evaluations = 1, halvings = 0, back = -1;
  double linear = o.linear_step, angular = o.angular_step;
  while (evaluations < o.max_iterations) {
    const Pose2 moves[6] = {
        {pose.x + linear, pose.y, pose.theta},  {pose.x - linear, pose.y, pose.theta},
        {pose.x, pose.y + linear, pose.theta},  {pose.x, pose.y - linear, pose.theta},
        {pose.x, pose.y, pose.theta + angular}, {pose.x, pose.y, pose.theta - angular}};
    int chosen = -1;
    for (int k = 0; k < 6 && evaluations < o.max_iterations; ++k) {
      ++evaluations;
      if (k == back) continue;
      const double score = m.score(grid, points, moves[k]);
      if (score > best) {
        best = score;
        chosen = k;
      }
    }
    back = -1;
    if (chosen >= 0) {
      pose = moves[chosen];
      back = chosen ^ 1;
    } else {
      if (++halvings > o.refinements) break;
      linear *= 0.5;
      angular *= 0.5;
    }
  }
  r.pose = pose;
  r.score = best;
  r.evaluations = evaluations;
  return r;
}
}  // namespace

TEST_CASE("matching and proposal fits on a tiled grid equal one pose at a time",
          "[scan_matcher][occupancy_rows]") {
  // match() and fitProposal() score their poses together, in clusters of nearby endpoints, and
  // skip moves onto poses scored before. Wide steps and kernels split the clusters, many
  // proposal samples fill several groups; everything must equal scoring one pose at a time
  // (plain hill climbing on score(), the cell-by-cell walk's likelihoods).
  const World world = room();
  const Laser laser;
  const TiledGrid grid = mapOf(world, laser, roomMappingPoses(), 3, TiledGrid());
  const CellByCell walk(grid);
  std::mt19937_64 rng(29);
  const std::vector<Pose2> truths = roomMappingPoses();
  int matched = 0;
  for (int radius : {1, 2, 4, 14})
    for (double step : {0.05, 0.6}) {
      ScanMatcherOptions o;
      o.kernel_radius = radius;
      o.linear_step = step;
      o.angular_step = step;
      o.beam_step = 3;
      o.compute_covariance = false;
      o.proposal_linear = step / 2;
      o.proposal_steps = radius == 2 ? 3 : 1;  // 343 samples: eleven groups
      const ScanMatcher m(o);
      for (std::size_t t = 0; t < 3; ++t) {
        const Pose2& truth = truths[(t * 3 + static_cast<std::size_t>(radius)) % truths.size()];
        const ScanPoints points =
            m.prepare(laser.view(simulate(world, laser, truth, rng)), laser.mount);
        const Pose2 start(truth.x + 0.07, truth.y - 0.06, truth.theta + 0.04);
        INFO("radius " << radius << ", step " << step << ", pose " << t);
        const MatchResult a = m.match(grid, points, start);
        const MatchResult b = plainHillClimb(m, grid, points, start);
        REQUIRE(a.pose.x == b.pose.x);
        REQUIRE(a.pose.y == b.pose.y);
        REQUIRE(a.pose.theta == b.pose.theta);
        REQUIRE(a.score == b.score);
        REQUIRE(a.evaluations == b.evaluations);
        if (a.success) ++matched;
        const Eigen::Matrix3d prior = Eigen::Vector3d(0.01, 0.01, 0.003).asDiagonal();
        const ProposalFit fa = m.fitProposal(grid, points, a.pose, start, prior);
        const ProposalFit fb = m.fitProposal(walk, points, a.pose, start, prior);
        REQUIRE(fa.log_eta == fb.log_eta);
        REQUIRE(fa.mean.x == fb.mean.x);
        REQUIRE(fa.mean.y == fb.mean.y);
        REQUIRE(fa.mean.theta == fb.mean.theta);
        REQUIRE(fa.covariance == fb.covariance);
      }
    }
  CHECK(matched > 12);
}
