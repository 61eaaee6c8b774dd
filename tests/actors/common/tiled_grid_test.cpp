// Tests for the copy-on-write tiled occupancy grid: same cells as OccupancyGrid, tile sharing
// between copies, bad input, growth and concurrent writes to copies.
#include <tessera/common/occupancy_grid.hpp>
#include <tessera/common/pose2.hpp>
#include <tessera/common/tiled_grid.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <set>
#include <thread>
#include <utility>
#include <vector>

using tessera::common::CellBox;
using tessera::common::OccupancyGrid;
using tessera::common::OccupancyMap;
using tessera::common::Pose2;
using tessera::common::RangeScan;
using tessera::common::ScanInsertOptions;
using tessera::common::ScanInsertResult;
using tessera::common::TiledGrid;

namespace {
constexpr double kPi = std::numbers::pi;
constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr int kBeams = 181;

/// A scan with its own range storage (RangeScan only borrows).
struct OwnedScan {
  std::vector<float> ranges;
  Pose2 pose;
  RangeScan view() const { return RangeScan{ranges, -kPi / 2, kPi / (kBeams - 1), 0.1, 8.0}; }
};

/// Random ranges (some no-return, some NaN, some past max_range) from a random pose in a
/// box around `centre`, so scans overlap and reach negative cell indices.
OwnedScan randomScan(std::mt19937& rng, const Eigen::Vector2d& centre, double spread) {
  std::uniform_real_distribution<double> pos(-spread, spread), angle(-kPi, kPi);
  std::uniform_real_distribution<float> range(0.3f, 7.5f), pick(0.0f, 1.0f);
  OwnedScan s;
  s.pose = Pose2(centre.x() + pos(rng), centre.y() + pos(rng), angle(rng));
  for (int k = 0; k < kBeams; ++k) {
    const float p = pick(rng);
    s.ranges.push_back(p < 0.05f ? kInf : p < 0.08f ? kNaN : range(rng));
  }
  return s;
}

std::vector<OwnedScan> randomScans(unsigned seed, int n, const Eigen::Vector2d& centre,
                                   double spread) {
  std::mt19937 rng(seed);
  std::vector<OwnedScan> scans;
  for (int i = 0; i < n; ++i) scans.push_back(randomScan(rng, centre, spread));
  return scans;
}

// Short returns past max_range (6 m) clear without an endpoint; no-returns clear 3 m.
const ScanInsertOptions kInsert{.max_range = 6.0, .max_free_range = 3.0};

TiledGrid::Options tiledOptions(double resolution, int max_side_cells = 16384) {
  TiledGrid::Options o;
  o.resolution = resolution;
  o.max_side_cells = max_side_cells;
  return o;
}

OccupancyGrid::Options referenceOptions(double resolution) {
  OccupancyGrid::Options o;
  o.resolution = resolution;
  return o;
}

void insertAll(TiledGrid& grid, const std::vector<OwnedScan>& scans) {
  for (const OwnedScan& s : scans) grid.insertScan(s.view(), s.pose, kInsert);
}

CellBox unionBox(CellBox a, const CellBox& b) {
  if (!b.empty()) {
    a.extend(b.min);
    a.extend(b.max);
  }
  return a;
}

/// Cells (not storage) are identical: same known set and the same fixed-point values.
bool sameCells(const TiledGrid& a, const TiledGrid& b) {
  if (a.knownCount() != b.knownCount()) return false;
  const CellBox box = unionBox(a.knownBounds(), b.knownBounds());
  for (int j = box.min.y(); j <= box.max.y(); ++j)
    for (int i = box.min.x(); i <= box.max.x(); ++i)
      if (a.isKnown({i, j}) != b.isKnown({i, j}) || a.logOdds({i, j}) != b.logOdds({i, j}))
        return false;
  return true;
}

Eigen::Vector2i tileOf(const Eigen::Vector2i& c) {
  return {c.x() >> TiledGrid::kTileBits, c.y() >> TiledGrid::kTileBits};
}

/// Tiles holding at least one known cell of `grid` within `box`.
std::set<std::pair<int, int>> knownTiles(const TiledGrid& grid, const CellBox& box) {
  std::set<std::pair<int, int>> tiles;
  for (int j = box.min.y(); j <= box.max.y(); ++j)
    for (int i = box.min.x(); i <= box.max.x(); ++i)
      if (grid.isKnown({i, j})) tiles.insert({tileOf({i, j}).x(), tileOf({i, j}).y()});
  return tiles;
}

TiledGrid::Counters countersSince(const TiledGrid::Counters& before) {
  const TiledGrid::Counters now = TiledGrid::counters();
  return {now.tiles_allocated - before.tiles_allocated, now.tiles_cloned - before.tiles_cloned};
}
}  // namespace

TEST_CASE("TiledGrid holds the same cells as OccupancyGrid after random scans", "[tiled_grid]") {
  constexpr int kScans = 12;
  const auto scans = randomScans(7, kScans, {-1.0, -2.0}, 3.0);
  OccupancyGrid reference(referenceOptions(0.05));
  TiledGrid grid(tiledOptions(0.05));
  for (const OwnedScan& s : scans) {
    const ScanInsertResult r = reference.insertScan(s.view(), s.pose, kInsert);
    const ScanInsertResult t = grid.insertScan(s.view(), s.pose, kInsert);
    CHECK(t.hits == r.hits);
    CHECK(t.no_return == r.no_return);
    CHECK(t.beyond_range == r.beyond_range);
    CHECK(t.invalid == r.invalid);
    CHECK(t.clipped_cells == 0);
    CHECK(r.clipped_cells == 0);
  }
  REQUIRE(grid.knownCount() == reference.knownCount());
  REQUIRE(grid.knownBounds().min == reference.knownBounds().min);
  REQUIRE(grid.knownBounds().max == reference.knownBounds().max);
  CHECK(grid.knownBounds().min.x() < 0);
  CHECK(grid.knownBounds().min.y() < 0);

  // Each update rounds its increment to 1/1024, so the error grows by at most half a step per
  // scan (and the clamp bounds are rounded once).
  const float tolerance = (kScans + 1) * 0.5f / TiledGrid::kLogOddsScale;
  CellBox box = reference.knownBounds();
  box.min -= Eigen::Vector2i(3, 3);
  box.max += Eigen::Vector2i(3, 3);
  std::size_t mismatched_known = 0, mismatched_value = 0, ros_off = 0;
  for (int j = box.min.y(); j <= box.max.y(); ++j) {
    for (int i = box.min.x(); i <= box.max.x(); ++i) {
      const Eigen::Vector2i c(i, j);
      mismatched_known += grid.isKnown(c) != reference.isKnown(c);
      mismatched_value += std::abs(grid.logOdds(c) - reference.logOdds(c)) > tolerance;
      ros_off += std::abs(grid.probability(c) - reference.probability(c)) > tolerance;
    }
  }
  CHECK(mismatched_known == 0);
  CHECK(mismatched_value == 0);
  CHECK(ros_off == 0);

  // ROS export: identical up to a percent where quantisation crosses a rounding boundary.
  const OccupancyMap a = grid.toOccupancyMap(), b = reference.toOccupancyMap();
  REQUIRE(a.width == b.width);
  REQUIRE(a.height == b.height);
  CHECK(a.origin.x == b.origin.x);
  CHECK(a.origin.y == b.origin.y);
  std::size_t export_off = 0;
  for (std::size_t k = 0; k < a.cells.size(); ++k)
    export_off += std::abs(a.cells[k] - b.cells[k]) > 1 || (a.cells[k] < 0) != (b.cells[k] < 0);
  CHECK(export_off == 0);
  std::vector<std::int8_t> wrong(3);
  CHECK_THROWS_AS(grid.exportInt8(grid.knownBounds(), wrong), std::invalid_argument);
}

TEST_CASE("TiledGrid cell geometry matches OccupancyGrid", "[tiled_grid]") {
  const TiledGrid grid(tiledOptions(0.1));
  const OccupancyGrid reference(referenceOptions(0.1));
  for (const Eigen::Vector2d& p : {Eigen::Vector2d(0.0, 0.0), Eigen::Vector2d(-0.05, 0.05),
                                   Eigen::Vector2d(12.34, -5.67), Eigen::Vector2d(-100.01, 3.0)}) {
    const Eigen::Vector2i c = grid.worldToCell(p);
    CHECK(c == reference.worldToCell(p));
    CHECK(grid.cellCenter(c) == reference.cellCenter(c));
    CHECK(grid.cellCorner(c) == reference.cellCorner(c));
  }
  CHECK_FALSE(grid.isKnown({0, 0}));
  CHECK(grid.logOdds({-5, 7}) == 0.0f);
  CHECK(grid.probability({-5, 7}) == 0.5);
  CHECK(grid.toOccupancyMap().empty());
}

TEST_CASE("copying a TiledGrid shares its tiles and a write clones only the tiles it touches",
          "[tiled_grid]") {
  TiledGrid original(tiledOptions(0.05));
  const auto base = randomScans(11, 1, {0.0, 0.0}, 0.5);
  insertAll(original, base);
  const std::size_t tiles = original.tileCount();
  REQUIRE(tiles > 4);
  CHECK(original.uniqueTileCount() == tiles);

  auto before = TiledGrid::counters();
  TiledGrid copy(original);
  auto delta = countersSince(before);
  CHECK(delta.tiles_allocated == 0);
  CHECK(delta.tiles_cloned == 0);
  CHECK(copy.tileCount() == tiles);
  CHECK(copy.uniqueTileCount() == 0);
  CHECK(original.uniqueTileCount() == 0);
  CHECK(sameCells(copy, original));

  // A short scan from elsewhere: every cell it touches changes value (nothing is at a clamp
  // bound after one scan), so the tiles that differ are exactly the tiles it wrote.
  TiledGrid snapshot(original.options());
  insertAll(snapshot, base);
  std::vector<float> ranges(kBeams, 1.2f);
  const RangeScan scan{ranges, -kPi / 2, kPi / (kBeams - 1), 0.1, 8.0};
  const Pose2 pose(0.7, -0.4, 0.3);
  before = TiledGrid::counters();
  copy.insertScan(scan, pose, kInsert);
  delta = countersSince(before);

  CHECK(sameCells(original, snapshot));  // the original did not see the write
  std::set<std::pair<int, int>> changed, cloned;
  const CellBox box = unionBox(original.knownBounds(), copy.knownBounds());
  const auto had = knownTiles(original, box);
  for (int j = box.min.y(); j <= box.max.y(); ++j) {
    for (int i = box.min.x(); i <= box.max.x(); ++i) {
      const Eigen::Vector2i c(i, j);
      if (copy.isKnown(c) == original.isKnown(c) && copy.logOdds(c) == original.logOdds(c))
        continue;
      const std::pair<int, int> t{tileOf(c).x(), tileOf(c).y()};
      changed.insert(t);
      if (had.count(t) != 0) cloned.insert(t);
    }
  }
  REQUIRE_FALSE(changed.empty());
  CHECK(cloned.size() < tiles);  // the scan touched only part of the map
  CHECK(delta.tiles_cloned == cloned.size());
  CHECK(delta.tiles_allocated == changed.size() - cloned.size());
  CHECK(copy.uniqueTileCount() == changed.size());
  CHECK(original.uniqueTileCount() == cloned.size());  // the copy let go of those
  CHECK(copy.tileCount() == tiles + delta.tiles_allocated);

  SECTION("a second write to the same tiles clones nothing") {
    before = TiledGrid::counters();
    copy.insertScan(scan, pose, kInsert);
    delta = countersSince(before);
    CHECK(delta.tiles_cloned == 0);
    CHECK(delta.tiles_allocated == 0);
  }
  SECTION("assignment and moves share or transfer tiles without cloning") {
    before = TiledGrid::counters();
    TiledGrid assigned(tiledOptions(0.1));
    assigned = original;
    CHECK(assigned.options().resolution == 0.05);
    CHECK(sameCells(assigned, original));
    TiledGrid moved(std::move(assigned));
    CHECK(assigned.tileCount() == 0);  // documented: a moved-from grid is empty
    CHECK(assigned.knownCount() == 0);
    CHECK(sameCells(moved, original));
    TiledGrid target(tiledOptions(0.05));
    insertAll(target, base);
    const std::size_t own = target.tileCount();
    target = std::move(moved);
    CHECK(sameCells(target, original));
    delta = countersSince(before);
    CHECK(delta.tiles_cloned == 0);
    CHECK(delta.tiles_allocated == own);  // only the map `target` built itself
  }
}

TEST_CASE("copies of a TiledGrid cost about one map of memory, not one per copy", "[tiled_grid]") {
  TiledGrid grid(tiledOptions(0.05));
  insertAll(grid, randomScans(3, 10, {0.0, 0.0}, 4.0));
  const std::size_t tiles = grid.tileCount();
  REQUIRE(tiles > 50);
  CHECK(grid.memoryBytes() >= tiles * TiledGrid::tileBytes());
  CHECK(TiledGrid::tileBytes() < 2100);  // 2 KiB of cells plus the count

  constexpr int kCopies = 50;
  std::vector<TiledGrid> particles(kCopies, grid);
  for (const TiledGrid& p : particles) {
    CHECK(p.tileCount() == tiles);
    CHECK(p.uniqueTileCount() == 0);
  }
  // Each particle integrates one short scan of its own: it pays only for the tiles it wrote.
  const auto before = TiledGrid::counters();
  std::vector<float> ranges(kBeams, 1.0f);
  const RangeScan scan{ranges, -kPi / 2, kPi / (kBeams - 1), 0.1, 8.0};
  std::size_t unique = 0;
  for (int k = 0; k < kCopies; ++k) {
    particles[k].insertScan(scan, Pose2(0.02 * k, -0.01 * k, 0.1 * k), kInsert);
    unique += particles[k].uniqueTileCount();
  }
  const auto delta = countersSince(before);
  CHECK(unique == delta.tiles_cloned + delta.tiles_allocated);
  // Distinct tiles alive: the shared map plus what the particles wrote, far from N× the map.
  const std::size_t alive = tiles + unique;
  CHECK(alive < 3 * tiles);
  CHECK(alive * 10 < static_cast<std::size_t>(kCopies) * tiles);
  // Only tiles every particle rewrote (around the common sensor area) are the original's alone.
  CHECK(grid.uniqueTileCount() < tiles / 4);
}

TEST_CASE("TiledGrid counts bad scans and leaves the grid untouched", "[tiled_grid]") {
  TiledGrid grid(tiledOptions(0.1));
  const auto snapshot_before = TiledGrid::counters();
  auto untouched = [&] {
    CHECK(grid.knownCount() == 0);
    CHECK(grid.tileCount() == 0);
    CHECK(grid.memoryBytes() == 0);  // not even the table grew
    CHECK(countersSince(snapshot_before).tiles_allocated == 0);
  };

  const std::vector<float> nan{kNaN, kNaN, -1.0f, 0.0f, 0.05f};
  const auto r_nan = grid.insertScan(RangeScan{nan, 0.0, 0.01, 0.1, 20.0}, Pose2());
  CHECK(r_nan.invalid == 5);
  CHECK_FALSE(r_nan.used());
  untouched();

  const auto r_empty = grid.insertScan(RangeScan{{}, 0.0, 0.01, 0.1, 20.0}, Pose2());
  CHECK_FALSE(r_empty.used());
  CHECK(r_empty.invalid == 0);
  untouched();

  // All beams without a return, with clearing disabled: counted, nothing to write.
  const std::vector<float> max_range{kInf, 20.0f, 25.0f};
  const auto r_max = grid.insertScan(RangeScan{max_range, 0.0, 0.5, 0.1, 20.0}, Pose2(),
                                     {.max_range = 30.0, .max_free_range = 0.0});
  CHECK(r_max.no_return == 3);
  CHECK(r_max.used());
  untouched();

  const std::vector<float> ok{1.0f, 2.0f};
  for (const Pose2& p : {Pose2(std::nan(""), 0.0, 0.0), Pose2(0.0, kInf, 0.0),
                         Pose2(0.0, 0.0, -kInf), Pose2(1e12, 0.0, 0.0)}) {
    const auto r = grid.insertScan(RangeScan{ok, 0.0, 0.1, 0.1, 20.0}, p);
    CHECK(r.invalid == 2);
    CHECK_FALSE(r.used());
  }
  const auto r_angle = grid.insertScan(RangeScan{ok, std::nan(""), 0.1, 0.1, 20.0}, Pose2());
  CHECK(r_angle.invalid == 2);
  untouched();
}

TEST_CASE("TiledGrid grows in negative directions without moving or cloning tiles",
          "[tiled_grid]") {
  TiledGrid grid(tiledOptions(0.1));
  OccupancyGrid reference(referenceOptions(0.1));
  const std::vector<float> r{1.0f};
  const RangeScan beam{r, 0.0, 0.0, 0.1, 20.0};
  const auto before = TiledGrid::counters();
  const Pose2 start(0.05, 0.05, 0.0);
  grid.insertScan(beam, start);
  reference.insertScan(beam, start);
  const float hit = grid.logOdds({10, 0});
  CHECK(hit == Approx(grid.options().log_odds.hit).margin(1e-3));
  for (const Pose2& p : {Pose2(-30.0, 0.0, kPi), Pose2(0.0, -40.0, -kPi / 2),
                         Pose2(-25.0, -25.0, -3 * kPi / 4), Pose2(20.0, 15.0, 0.0)}) {
    grid.insertScan(beam, p);
    reference.insertScan(beam, p);
    CHECK(grid.isKnown(grid.worldToCell(p.translation())));
  }
  CHECK(grid.knownBounds().min.x() <= -300);
  CHECK(grid.knownBounds().min.y() <= -400);
  CHECK(grid.knownBounds().min == reference.knownBounds().min);
  CHECK(grid.knownBounds().max == reference.knownBounds().max);
  CHECK(grid.knownCount() == reference.knownCount());
  CHECK(grid.logOdds({10, 0}) == hit);  // first cells kept their place and value
  CHECK(grid.logOdds({5, 0}) == Approx(grid.options().log_odds.miss).margin(1e-3));
  // Five short beams in separate places: a handful of tiles, and growth moved pointers only.
  const auto delta = countersSince(before);
  CHECK(delta.tiles_cloned == 0);
  CHECK(delta.tiles_allocated == grid.tileCount());
  CHECK(grid.tileCount() <= 10);
}

TEST_CASE("TiledGrid max_side_cells caps the table and counts clipped updates", "[tiled_grid]") {
  TiledGrid grid(tiledOptions(0.1, 64));  // two tiles per axis
  const std::vector<float> r{10.0f};
  const RangeScan beam{r, 0.0, 0.0, 0.1, 20.0};
  const auto res = grid.insertScan(beam, Pose2(0.05, 0.05, 0.0));
  CHECK(res.hits == 1);
  CHECK(res.clipped_cells > 0);
  CHECK(grid.isKnown({0, 0}));  // the sensor's neighbourhood is kept
  CHECK(grid.knownBounds().width() <= 64);
  const std::size_t known = grid.knownCount();
  CHECK(known + res.clipped_cells == 101);  // every cell of the beam: kept or counted

  const auto far = grid.insertScan(beam, Pose2(500.0, 0.0, 0.0));
  CHECK(far.clipped_cells == 101);
  CHECK(grid.knownCount() == known);  // what was mapped stays mapped
  CHECK(grid.knownBounds().width() <= 64);
  CHECK(grid.tileCount() <= 4);
}

TEST_CASE("concurrent writes to TiledGrid copies match serially built grids", "[tiled_grid]") {
  const auto base_scans = randomScans(21, 6, {0.0, 0.0}, 2.0);
  TiledGrid base(tiledOptions(0.05));
  insertAll(base, base_scans);
  TiledGrid base_reference(base.options());
  insertAll(base_reference, base_scans);

  for (unsigned round = 0; round < 8; ++round) {
    // Both threads write over the shared map, so they clone the same shared tiles at once.
    const auto scans_a = randomScans(100 + round, 4, {0.0, 0.0}, 2.0);
    const auto scans_b = randomScans(200 + round, 4, {0.0, 0.0}, 2.0);
    TiledGrid a(base), b(base);
    std::thread ta([&] { insertAll(a, scans_a); });
    std::thread tb([&] { insertAll(b, scans_b); });
    ta.join();
    tb.join();

    TiledGrid reference_a(base.options()), reference_b(base.options());
    insertAll(reference_a, base_scans);
    insertAll(reference_a, scans_a);
    insertAll(reference_b, base_scans);
    insertAll(reference_b, scans_b);
    INFO("round " << round);
    CHECK(sameCells(a, reference_a));
    CHECK(sameCells(b, reference_b));
    CHECK(sameCells(base, base_reference));
  }
}

TEST_CASE("invalid TiledGrid options are rejected", "[tiled_grid]") {
  auto with = [](auto change) {
    TiledGrid::Options o;
    change(o);
    return o;
  };
  using O = TiledGrid::Options;
  CHECK_NOTHROW(TiledGrid(O{}));
  CHECK_THROWS_AS(TiledGrid(tiledOptions(0.0)), std::invalid_argument);
  CHECK_THROWS_AS(TiledGrid(tiledOptions(std::nan(""))), std::invalid_argument);
  CHECK_THROWS_AS(TiledGrid(tiledOptions(0.05, 0)), std::invalid_argument);
  CHECK_THROWS_AS(TiledGrid(with([](O& o) { o.log_odds.hit = -1.0f; })), std::invalid_argument);
  CHECK_THROWS_AS(TiledGrid(with([](O& o) { o.log_odds.miss = 0.5f; })), std::invalid_argument);
  CHECK_THROWS_AS(TiledGrid(with([](O& o) { o.log_odds.min = 1.0f; })), std::invalid_argument);
  // Outside the int16 fixed-point range or below its step.
  CHECK_THROWS_AS(TiledGrid(with([](O& o) { o.log_odds.max = 40.0f; })), std::invalid_argument);
  CHECK_THROWS_AS(TiledGrid(with([](O& o) { o.log_odds.min = -kInf; })), std::invalid_argument);
  CHECK_THROWS_AS(TiledGrid(with([](O& o) { o.log_odds.hit = 1e-5f; })), std::invalid_argument);
}
