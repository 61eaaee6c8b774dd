// Tests for SE(2) math and the log-odds occupancy grid
// (docs/algorithms.md#occupancy-grid-log-odds).
#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

using tessera::Pose2;
using tessera::grid::CellBox;
using tessera::grid::OccupancyGrid;
using tessera::grid::OccupancyMap;
using tessera::grid::RangeScan;
using tessera::grid::ScanInsertOptions;

namespace {
constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

OccupancyGrid::Options gridOptions(double resolution, int chunk_cells = 64,
                                   int max_side_cells = 16384) {
  OccupancyGrid::Options o;
  o.resolution = resolution;
  o.chunk_cells = chunk_cells;
  o.max_side_cells = max_side_cells;
  return o;
}

RangeScan oneBeam(const std::vector<float>& r, double angle = 0.0) {
  return RangeScan{r, angle, 0.0, 0.1, 20.0};
}
}  // namespace

TEST_CASE("normalizeAngle maps angles into the half-open interval from -pi to pi", "[pose2]") {
  using tessera::normalizeAngle;
  CHECK(normalizeAngle(0.0) == 0.0);
  CHECK(normalizeAngle(std::numbers::pi) == Approx(std::numbers::pi));
  CHECK(normalizeAngle(-std::numbers::pi) ==
        Approx(std::numbers::pi));  // -pi belongs to the other end
  CHECK(normalizeAngle(3 * std::numbers::pi) == Approx(std::numbers::pi));
  CHECK(normalizeAngle(-3 * std::numbers::pi) == Approx(std::numbers::pi));
  CHECK(normalizeAngle(2 * std::numbers::pi + 0.25) == Approx(0.25));
  CHECK(normalizeAngle(-2 * std::numbers::pi - 0.25) == Approx(-0.25));
  CHECK(normalizeAngle(1e6) > -std::numbers::pi);
  CHECK(normalizeAngle(1e6) <= std::numbers::pi);
  CHECK(std::isnan(normalizeAngle(std::nan(""))));
  CHECK(tessera::angleDiff(-3.0, 3.0) == Approx(2 * std::numbers::pi - 6.0));
}

TEST_CASE("Pose2 compose, inverse, between and point transform agree", "[pose2]") {
  const Pose2 a(1.0, 2.0, 0.5), b(-0.3, 0.7, 2.9);
  const Pose2 ab = a * b;
  // Against the homogeneous matrix product.
  const Pose2 ab_m = Pose2::fromMatrix(a.matrix() * b.matrix());
  CHECK(ab.x == Approx(ab_m.x));
  CHECK(ab.y == Approx(ab_m.y));
  CHECK(ab.theta == Approx(ab_m.theta));
  CHECK(ab.theta <= std::numbers::pi);  // 0.5 + 2.9 > pi wraps
  CHECK(ab.theta == Approx(0.5 + 2.9 - 2 * std::numbers::pi));

  const Pose2 id = a * a.inverse();
  CHECK(id.x == Approx(0.0).margin(1e-12));
  CHECK(id.y == Approx(0.0).margin(1e-12));
  CHECK(id.theta == Approx(0.0).margin(1e-12));

  const Pose2 d = tessera::between(a, ab);
  CHECK(d.x == Approx(b.x));
  CHECK(d.y == Approx(b.y));
  CHECK(d.theta == Approx(b.theta));

  const Eigen::Vector2d p(0.4, -1.1);
  const Eigen::Vector2d q = (a * b) * p;
  const Eigen::Vector2d q2 = a * (b * p);
  CHECK(q.x() == Approx(q2.x()));
  CHECK(q.y() == Approx(q2.y()));
  const Eigen::Vector2d back = a.inverse() * (a * p);
  CHECK(back.x() == Approx(p.x()));
  CHECK(back.y() == Approx(p.y()));

  // 90 degrees: x axis of the child is y axis of the parent.
  const Eigen::Vector2d e = tessera::transformPoint(Pose2(1, 0, std::numbers::pi / 2), {1, 0});
  CHECK(e.x() == Approx(1.0));
  CHECK(e.y() == Approx(1.0));
}

TEST_CASE("Pose2 interpolation takes the short way round", "[pose2]") {
  const Pose2 a(0, 0, 3.0), b(2, -2, -3.0);
  const Pose2 m = tessera::interpolate(a, b, 0.5);
  CHECK(m.x == Approx(1.0));
  CHECK(m.y == Approx(-1.0));
  CHECK(std::abs(m.theta) == Approx(std::numbers::pi));  // through pi, not through 0
  const Pose2 end = tessera::interpolate(a, b, 1.0);
  CHECK(end.theta == Approx(-3.0));
}

TEST_CASE("world to cell conversion round-trips and is stable", "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.1));
  for (const Eigen::Vector2d& p : {Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(-0.05, 0.05),
                                   Eigen::Vector2d(12.34, -5.67), Eigen::Vector2d(-100.01, 3.0)}) {
    const Eigen::Vector2i c = grid.worldToCell(p);
    const Eigen::Vector2d center = grid.cellCenter(c);
    CHECK(std::abs(center.x() - p.x()) <= 0.05 + 1e-12);
    CHECK(std::abs(center.y() - p.y()) <= 0.05 + 1e-12);
    CHECK(grid.worldToCell(center) == c);
  }
  CHECK(grid.worldToCell({-0.05, 0.05}) == Eigen::Vector2i(-1, 0));
  CHECK(grid.cellCorner({2, -3}).isApprox(Eigen::Vector2d(0.2, -0.3)));
}

TEST_CASE("a beam marks free cells along the ray and its endpoint occupied", "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.1));
  // Sensor in the middle of cell (0,0), beam along +x hitting at 1.0 m: endpoint x = 1.05.
  const auto r = grid.insertScan(oneBeam({1.0f}), Pose2(0.05, 0.05, 0.0));
  CHECK(r.hits == 1);
  CHECK(r.invalid == 0);
  const auto& l = grid.options().log_odds;
  for (int i = 0; i < 10; ++i) {
    INFO("cell " << i);
    CHECK(grid.logOdds({i, 0}) == Approx(l.miss));
    CHECK(grid.probability({i, 0}) < 0.5);
  }
  CHECK(grid.logOdds({10, 0}) == Approx(l.hit));
  CHECK(grid.probability({10, 0}) > 0.5);
  CHECK_FALSE(grid.isKnown({11, 0}));
  CHECK_FALSE(grid.isKnown({5, 1}));
  CHECK(grid.knownCount() == 11);
  CHECK(grid.knownBounds().min == Eigen::Vector2i(0, 0));
  CHECK(grid.knownBounds().max == Eigen::Vector2i(10, 0));
}

TEST_CASE("diagonal and negative-direction rays reach their endpoint cell", "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.05));
  const Pose2 sensor(0.51, -0.22, 2.4);
  std::vector<float> ranges;
  for (int k = 0; k < 36; ++k) ranges.push_back(1.0f + 0.1f * k);
  const RangeScan scan{ranges, -std::numbers::pi, 2 * std::numbers::pi / 36, 0.05, 20.0};
  const auto r = grid.insertScan(scan, sensor);
  CHECK(r.hits == 36);
  for (int k = 0; k < 36; ++k) {
    const double a = sensor.theta + scan.angle_min + k * scan.angle_increment;
    const Eigen::Vector2d end =
        sensor.translation() + ranges[k] * Eigen::Vector2d(std::cos(a), std::sin(a));
    INFO("beam " << k);
    CHECK(grid.logOdds(grid.worldToCell(end)) > 0.0f);
    // Halfway along the beam is free (each cell at most once per scan).
    const Eigen::Vector2d mid = sensor.translation() + 0.5 * (end - sensor.translation());
    CHECK(grid.logOdds(grid.worldToCell(mid)) == Approx(grid.options().log_odds.miss));
  }
  // The sensor's own cell is free.
  CHECK(grid.logOdds(grid.worldToCell(sensor.translation())) < 0.0f);
}

TEST_CASE("log-odds are clamped to [l_min, l_max]", "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.1));
  const auto& l = grid.options().log_odds;
  for (int n = 0; n < 50; ++n) grid.insertScan(oneBeam({1.0f}), Pose2(0.05, 0.05, 0.0));
  CHECK(grid.logOdds({10, 0}) == Approx(l.max));
  CHECK(grid.logOdds({3, 0}) == Approx(l.min));
  CHECK(OccupancyGrid::rosValue(l.max) == 97);
  CHECK(OccupancyGrid::rosValue(l.min) == 12);
  CHECK(OccupancyGrid::rosValue(0.0f) == 50);
}

TEST_CASE("within one scan a hit wins over a miss and cells update once", "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.1));
  // Two beams: one ends at cell 5, the other passes through cell 5 and ends at cell 10.
  const std::vector<float> r{0.5f, 1.0f};
  const RangeScan s{r, 0.0, 0.0, 0.1, 20.0};
  grid.insertScan(s, Pose2(0.05, 0.05, 0.0));
  const auto& l = grid.options().log_odds;
  CHECK(grid.logOdds({5, 0}) == Approx(l.hit));
  CHECK(grid.logOdds({2, 0}) == Approx(l.miss));  // crossed twice, counted once
  CHECK(grid.logOdds({10, 0}) == Approx(l.hit));
}

TEST_CASE("no-return beams clear free space but mark nothing", "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.1));
  const ScanInsertOptions opts{.max_range = 30.0, .max_free_range = 2.0};
  const std::vector<float> r{kInf, 25.0f};  // range_max is 20: both are no-return
  const RangeScan scan{r, 0.0, std::numbers::pi / 2, 0.1, 20.0};
  const auto res = grid.insertScan(scan, Pose2(0.05, 0.05, 0.0), opts);
  CHECK(res.no_return == 2);
  CHECK(res.hits == 0);
  CHECK(res.used());
  const OccupancyMap map = grid.toOccupancyMap();
  for (auto v : map.cells) CHECK(v != 100);
  int occupied = 0;
  for (auto v : map.cells) occupied += v > 50;
  CHECK(occupied == 0);
  CHECK(grid.logOdds({19, 0}) < 0.0f);  // cleared up to 2 m along +x
  CHECK_FALSE(grid.isKnown({21, 0}));
  CHECK(grid.logOdds({0, 19}) < 0.0f);  // and along +y
  CHECK_FALSE(grid.isKnown({0, 21}));

  SECTION("max_free_range 0 disables clearing") {
    OccupancyGrid g2(gridOptions(0.1));
    const auto res2 = g2.insertScan(scan, Pose2(), {.max_range = 30.0, .max_free_range = 0.0});
    CHECK(res2.no_return == 2);
    CHECK(g2.knownCount() == 0);
  }
}

TEST_CASE("returns beyond max_range clear up to max_range without an endpoint",
          "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.1));
  const auto res = grid.insertScan(oneBeam({5.0f}), Pose2(0.05, 0.05, 0.0),
                                   {.max_range = 1.0, .max_free_range = 0.5});
  CHECK(res.beyond_range == 1);
  CHECK(grid.logOdds({9, 0}) < 0.0f);
  CHECK(grid.logOdds({10, 0}) < 0.0f);  // the cell at max_range is free, not occupied
  CHECK_FALSE(grid.isKnown({12, 0}));
}

TEST_CASE("NaN, negative, short and empty scans are counted and harmless", "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.1));
  const std::vector<float> r{kNaN, -1.0f, 0.05f, 0.0f, -kInf, 1.0f};
  const auto res = grid.insertScan(RangeScan{r, 0.0, 0.01, 0.1, 20.0}, Pose2(0.05, 0.05, 0.0));
  CHECK(res.invalid == 5);
  CHECK(res.hits == 1);

  const auto empty = grid.insertScan(RangeScan{{}, 0.0, 0.01, 0.1, 20.0}, Pose2());
  CHECK_FALSE(empty.used());
  CHECK(empty.invalid == 0);

  const std::vector<float> bad{kNaN, kNaN};
  const auto all_bad = grid.insertScan(RangeScan{bad, 0.0, 0.01, 0.1, 20.0}, Pose2());
  CHECK(all_bad.invalid == 2);
  CHECK_FALSE(all_bad.used());

  const std::size_t known = grid.knownCount();
  const std::vector<float> ok{1.0f};
  const auto bad_pose =
      grid.insertScan(RangeScan{ok, 0.0, 0.0, 0.1, 20.0}, Pose2(std::nan(""), 0.0, 0.0));
  CHECK(bad_pose.invalid == 1);
  const auto far_pose = grid.insertScan(RangeScan{ok, 0.0, 0.0, 0.1, 20.0}, Pose2(1e12, 0, 0));
  CHECK(far_pose.invalid == 1);
  const auto bad_angle =
      grid.insertScan(RangeScan{ok, std::nan(""), 0.0, 0.1, 20.0}, Pose2(0.05, 0.05, 0.0));
  CHECK(bad_angle.invalid == 1);
  CHECK(grid.knownCount() == known);
}

TEST_CASE("the grid grows in every direction keeping cells in place", "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.1, 8));
  grid.insertScan(oneBeam({1.0f}), Pose2(0.05, 0.05, 0.0));
  const CellBox first = grid.allocated();
  CHECK(first.width() % 8 == 0);
  const float hit = grid.logOdds({10, 0});
  // Far away in all four directions.
  for (const Pose2& p : {Pose2(-20.0, 0.0, 0.0), Pose2(20.0, 0.0, 0.0), Pose2(0.0, -15.0, 0.0),
                         Pose2(0.0, 15.0, 0.0)}) {
    grid.insertScan(oneBeam({1.0f}), p);
    CHECK(grid.isKnown(grid.worldToCell(p.translation())));
  }
  CHECK(grid.allocated().width() > first.width());
  CHECK(grid.allocated().min.x() <= -200);
  CHECK(grid.allocated().max.y() > 150);
  CHECK(grid.logOdds({10, 0}) == hit);
  CHECK(grid.logOdds({5, 0}) == Approx(grid.options().log_odds.miss));
}

TEST_CASE("max_side_cells caps growth and counts clipped updates", "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.1, 4, 16));
  const auto r = grid.insertScan(oneBeam({5.0f}), Pose2(0.05, 0.05, 0.0));
  CHECK(grid.allocated().width() <= 16);
  CHECK(grid.allocated().height() <= 16);
  CHECK(r.clipped_cells > 0);
  CHECK(grid.isKnown({0, 0}));  // the sensor's neighbourhood is kept
  const auto r2 = grid.insertScan(oneBeam({1.0f}), Pose2(100.0, 0.0, 0.0));
  CHECK(grid.allocated().width() <= 16);
  CHECK(r2.clipped_cells > 0);
  CHECK(grid.isKnown({0, 0}));  // what was mapped stays mapped
}

TEST_CASE("export to ROS int8 over the known box", "[occupancy_grid]") {
  OccupancyGrid grid(gridOptions(0.1));
  const std::vector<float> r{1.0f, 0.5f};
  grid.insertScan(RangeScan{r, 0.0, std::numbers::pi / 2, 0.1, 20.0}, Pose2(0.05, 0.05, 0.0));
  const OccupancyMap map = grid.toOccupancyMap();
  REQUIRE(map.width == 11);
  REQUIRE(map.height == 6);
  CHECK(map.origin.x == Approx(0.0));
  CHECK(map.origin.y == Approx(0.0));
  CHECK(map.resolution == Approx(0.1));
  CHECK(map.at(10, 0) == OccupancyGrid::rosValue(grid.options().log_odds.hit));
  CHECK(map.at(0, 5) == OccupancyGrid::rosValue(grid.options().log_odds.hit));
  CHECK(map.at(3, 0) == OccupancyGrid::rosValue(grid.options().log_odds.miss));
  CHECK(map.at(5, 3) == OccupancyMap::kUnknown);
  CHECK(map.cellOf(grid.cellCenter({10, 0})) == Eigen::Vector2i(10, 0));

  // A box larger than the grid pads with unknown.
  CellBox big{{-3, -3}, {20, 20}};
  std::vector<std::int8_t> cells(big.width() * big.height());
  grid.exportInt8(big, cells);
  CHECK(cells[0] == OccupancyMap::kUnknown);
  CHECK(cells[3 * big.width() + 3] == OccupancyGrid::rosValue(grid.options().log_odds.miss));
  std::vector<std::int8_t> wrong(3);
  CHECK_THROWS_AS(grid.exportInt8(big, wrong), std::invalid_argument);

  CHECK(OccupancyGrid().toOccupancyMap().empty());
}

TEST_CASE("invalid grid options are rejected", "[occupancy_grid]") {
  auto with = [](auto change) {
    OccupancyGrid::Options o;
    change(o);
    return o;
  };
  using O = OccupancyGrid::Options;
  CHECK_THROWS_AS(OccupancyGrid(gridOptions(0.0)), std::invalid_argument);
  CHECK_THROWS_AS(OccupancyGrid(gridOptions(std::nan(""))), std::invalid_argument);
  CHECK_THROWS_AS(OccupancyGrid(with([](O& o) { o.log_odds.hit = -1.0f; })), std::invalid_argument);
  CHECK_THROWS_AS(OccupancyGrid(with([](O& o) { o.log_odds.miss = 0.5f; })), std::invalid_argument);
  CHECK_THROWS_AS(OccupancyGrid(with([](O& o) { o.log_odds.min = 1.0f; })), std::invalid_argument);
  CHECK_THROWS_AS(OccupancyGrid(gridOptions(0.1, 0)), std::invalid_argument);
  CHECK_THROWS_AS(OccupancyGrid(gridOptions(0.1, 64, 0)), std::invalid_argument);
}
