// Tests for the copy-on-write tiled occupancy grid: same cells as OccupancyGrid, tile sharing
// between copies, bad input, growth and concurrent writes to copies; per-cell hit points.
// Longer than ~600 lines on purpose: one test file per source file, and the tile sharing has many
// cases.
#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>
#include <tessera/grid/tiled_grid.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <set>
#include <thread>
#include <utility>
#include <vector>

using tessera::Pose2;
using tessera::grid::CellBox;
using tessera::grid::OccupancyGrid;
using tessera::grid::OccupancyMap;
using tessera::grid::RangeScan;
using tessera::grid::ScanInsertOptions;
using tessera::grid::ScanInsertResult;
using tessera::grid::TiledGrid;

namespace {
constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr int kBeams = 181;

/// A scan with its own range storage (RangeScan only borrows).
struct OwnedScan {
  std::vector<float> ranges;
  Pose2 pose;
  RangeScan view() const {
    return RangeScan{ranges, -std::numbers::pi / 2, std::numbers::pi / (kBeams - 1), 0.1, 8.0};
  }
};

/// Random ranges (some no-return, some NaN, some past max_range) from a random pose in a
/// box around `centre`, so scans overlap and reach negative cell indices.
OwnedScan randomScan(std::mt19937& rng, const Eigen::Vector2d& centre, double spread) {
  std::uniform_real_distribution<double> pos(-spread, spread),
      angle(-std::numbers::pi, std::numbers::pi);
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
  // Shared tiles count half for each of the two grids: together, once.
  const double tile_bytes = static_cast<double>(TiledGrid::tileBytes());
  const double table_bytes = static_cast<double>(original.memoryBytes()) - tiles * tile_bytes;
  CHECK(original.sharedMemoryBytes() == Approx(0.5 * tiles * tile_bytes + table_bytes));
  CHECK(original.sharedMemoryBytes() + copy.sharedMemoryBytes() ==
        Approx(tiles * tile_bytes + 2 * table_bytes));

  // A short scan from elsewhere: every cell it touches changes value (nothing is at a clamp
  // bound after one scan), so the tiles that differ are exactly the tiles it wrote.
  TiledGrid snapshot(original.options());
  insertAll(snapshot, base);
  std::vector<float> ranges(kBeams, 1.2f);
  const RangeScan scan{ranges, -std::numbers::pi / 2, std::numbers::pi / (kBeams - 1), 0.1, 8.0};
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
  // 2 KiB of cells plus the count and the occupancy bit cache (128 bytes of bits and a key).
  CHECK(TiledGrid::tileBytes() < 2200);

  constexpr int kCopies = 50;
  std::vector<TiledGrid> particles(kCopies, grid);
  for (const TiledGrid& p : particles) {
    CHECK(p.tileCount() == tiles);
    CHECK(p.uniqueTileCount() == 0);
  }
  // Each particle integrates one short scan of its own: it pays only for the tiles it wrote.
  const auto before = TiledGrid::counters();
  std::vector<float> ranges(kBeams, 1.0f);
  const RangeScan scan{ranges, -std::numbers::pi / 2, std::numbers::pi / (kBeams - 1), 0.1, 8.0};
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
  for (const Pose2& p :
       {Pose2(-30.0, 0.0, std::numbers::pi), Pose2(0.0, -40.0, -std::numbers::pi / 2),
        Pose2(-25.0, -25.0, -3 * std::numbers::pi / 4), Pose2(20.0, 15.0, 0.0)}) {
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

namespace {
/// Writes two copies of one base grid from two threads at once, round after round, so both
/// clone the same shared tiles concurrently; each copy, and the base, must equal grids built
/// serially from the same scans. make(seed, n) gives n scans, insert(grid, scans) adds them,
/// same(a, b) compares grids.
template <class Make, class Insert, class Same>
void checkConcurrentCopies(const TiledGrid::Options& options, Make make, int base_scans_n,
                           int round_scans_n, Insert insert, Same same) {
  const auto base_scans = make(21u, base_scans_n);
  TiledGrid base(options);
  insert(base, base_scans);
  TiledGrid base_reference(options);
  insert(base_reference, base_scans);

  for (unsigned round = 0; round < 8; ++round) {
    const auto scans_a = make(100 + round, round_scans_n);
    const auto scans_b = make(200 + round, round_scans_n);
    TiledGrid a(base), b(base);
    std::thread ta([&] { insert(a, scans_a); });
    std::thread tb([&] { insert(b, scans_b); });
    ta.join();
    tb.join();

    TiledGrid reference_a(options), reference_b(options);
    insert(reference_a, base_scans);
    insert(reference_a, scans_a);
    insert(reference_b, base_scans);
    insert(reference_b, scans_b);
    INFO("round " << round);
    CHECK(same(a, reference_a));
    CHECK(same(b, reference_b));
    CHECK(same(base, base_reference));
  }
}
}  // namespace

TEST_CASE("concurrent writes to TiledGrid copies match serially built grids", "[tiled_grid]") {
  checkConcurrentCopies(
      tiledOptions(0.05),
      [](unsigned seed, int n) {
        return randomScans(seed, n, {0.0, 0.0}, 2.0);
      },
      6, 4, insertAll, sameCells);
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

// ---- hit points (track_hit_points) ----

namespace {
/// A convex room: the walls are lines n·p = offset with unit normals pointing out, so a ray
/// from inside leaves through the nearest wall ahead. Exact ranges, so only the grid quantises.
struct ConvexRoom {
  std::vector<std::pair<Eigen::Vector2d, double>> walls;  // (normal, offset [m])

  /// A square of half-size `half` around `centre`, rotated by `angle`.
  static ConvexRoom square(const Eigen::Vector2d& centre, double half, double angle) {
    ConvexRoom room;
    for (int k = 0; k < 4; ++k) {
      const double a = angle + k * std::numbers::pi / 2;
      const Eigen::Vector2d n(std::cos(a), std::sin(a));
      room.walls.push_back({n, n.dot(centre) + half});
    }
    return room;
  }
  double range(const Eigen::Vector2d& o, double angle) const {
    const Eigen::Vector2d d(std::cos(angle), std::sin(angle));
    double best = std::numeric_limits<double>::infinity();
    for (const auto& [n, offset] : walls) {
      const double along = n.dot(d);
      if (along > 1e-12) best = std::min(best, (offset - n.dot(o)) / along);
    }
    return best;
  }
};

OwnedScan roomScan(const ConvexRoom& room, const Pose2& pose) {
  OwnedScan s;
  s.pose = pose;
  const RangeScan geometry = s.view();
  for (int k = 0; k < kBeams; ++k)
    s.ranges.push_back(static_cast<float>(room.range(
        pose.translation(), pose.theta + geometry.angle_min + k * geometry.angle_increment)));
  return s;
}

std::vector<OwnedScan> roomScans(unsigned seed, int n) {
  const ConvexRoom room = ConvexRoom::square({0.41, -0.27}, 2.6, 0.3);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> pos(-1.5, 1.5), angle(-std::numbers::pi, std::numbers::pi);
  std::vector<OwnedScan> scans;
  for (int i = 0; i < n; ++i)
    scans.push_back(roomScan(room, Pose2(0.41 + pos(rng), -0.27 + pos(rng), angle(rng))));
  return scans;
}

const ScanInsertOptions kRoomInsert{.max_range = 7.9, .max_free_range = 3.0};

TiledGrid::Options trackedOptions(double resolution) {
  TiledGrid::Options o = tiledOptions(resolution);
  o.track_hit_points = true;
  return o;
}

void insertRoom(TiledGrid& grid, const std::vector<OwnedScan>& scans) {
  for (const OwnedScan& s : scans) grid.insertScan(s.view(), s.pose, kRoomInsert);
}

/// Same cells and the same hit points (position and count) everywhere.
bool sameHits(const TiledGrid& a, const TiledGrid& b) {
  if (!sameCells(a, b)) return false;
  const CellBox box = unionBox(a.knownBounds(), b.knownBounds());
  for (int j = box.min.y(); j <= box.max.y(); ++j)
    for (int i = box.min.x(); i <= box.max.x(); ++i)
      if (a.hitPoint({i, j}) != b.hitPoint({i, j}) || a.hitCount({i, j}) != b.hitCount({i, j}))
        return false;
  return true;
}
}  // namespace

TEST_CASE("TiledGrid hit points are the mean of the endpoints that hit each cell", "[tiled_grid]") {
  const double res = 0.05;
  TiledGrid grid(trackedOptions(res));
  TiledGrid plain(tiledOptions(res));
  const auto scans = roomScans(5, 20);
  insertRoom(grid, scans);
  insertRoom(plain, scans);
  CHECK(grid.tracksHitPoints());
  CHECK_FALSE(plain.tracksHitPoints());
  CHECK(sameCells(grid, plain));  // tracking changes no log-odds

  // Reference: every endpoint, computed as the rasteriser does (in cell units), per cell.
  struct Sum {
    Eigen::Vector2d offset = Eigen::Vector2d::Zero();  // Σ (endpoint − centre) [cells]
    int n = 0;
  };
  std::map<std::pair<int, int>, Sum> sums;
  for (const OwnedScan& s : scans) {
    const RangeScan v = s.view();
    const Eigen::Vector2d origin = s.pose.translation() / res;
    for (int k = 0; k < kBeams; ++k) {
      const double r = v.ranges[static_cast<std::size_t>(k)];
      REQUIRE(r < kRoomInsert.max_range);
      const double a = s.pose.theta + v.angle_min + k * v.angle_increment;
      const Eigen::Vector2d end = origin + (r / res) * Eigen::Vector2d(std::cos(a), std::sin(a));
      const Eigen::Vector2i c(static_cast<int>(std::floor(end.x())),
                              static_cast<int>(std::floor(end.y())));
      Sum& sum = sums[{c.x(), c.y()}];
      sum.offset += end - c.cast<double>() - Eigen::Vector2d(0.5, 0.5);
      ++sum.n;
    }
  }
  REQUIRE(sums.size() > 300);

  // Each hit rounds the mean to 1/256 cell; rounding errors are averaged down with the later
  // hits, so after n hits the error is at most (n + 1)/4 steps (plus one where an endpoint
  // within 1/256 of the upper edge is clamped into the cell).
  const double unit = res / TiledGrid::kHitScale;
  double squared_steps = 0.0;
  int checked = 0, max_n = 0;
  for (const auto& [key, sum] : sums) {
    const Eigen::Vector2i c(key.first, key.second);
    INFO("cell " << c.transpose() << " hits " << sum.n);
    CHECK(grid.hitCount(c) == std::min(sum.n, 255));
    CHECK(plain.hitCount(c) == 0);
    CHECK(plain.hitPoint(c) == plain.cellCenter(c));
    const Eigen::Vector2d p = grid.hitPoint(c);
    CHECK(grid.worldToCell(p) == c);
    max_n = std::max(max_n, sum.n);
    if (sum.n > TiledGrid::kHitWindow) continue;
    const Eigen::Vector2d mean = grid.cellCenter(c) + (sum.offset / sum.n) * res;
    const double bound = ((sum.n + 1) / 4.0 + 1.0) * unit;
    CHECK(std::abs(p.x() - mean.x()) <= bound);
    CHECK(std::abs(p.y() - mean.y()) <= bound);
    squared_steps += ((p - mean) / unit).squaredNorm() / 2;
    ++checked;
  }
  CHECK(max_n > 4);
  REQUIRE(checked > 300);
  CHECK(std::sqrt(squared_steps / checked) < 1.0);  // typically within one storage step

  // Cells crossed but never hit keep their centre.
  std::size_t free_cells = 0;
  const CellBox box = grid.knownBounds();
  for (int j = box.min.y(); j <= box.max.y(); ++j)
    for (int i = box.min.x(); i <= box.max.x(); ++i)
      if (grid.isKnown({i, j}) && sums.count({i, j}) == 0) {
        ++free_cells;
        CHECK(grid.hitPoint({i, j}) == grid.cellCenter({i, j}));
      }
  CHECK(free_cells > 1000);
}

TEST_CASE("TiledGrid hit point follows slowly after 32 hits and the count saturates",
          "[tiled_grid]") {
  TiledGrid grid(trackedOptions(0.05));
  // Beams from (0.01, 0.01) along +x: 1.0 m ends at x = 1.01 (cell 20, 0.3 cell below its
  // centre), 1.03 m at x = 1.04 (0.3 cell above).
  auto repeat = [&](float range, int beams) {
    const std::vector<float> ranges(static_cast<std::size_t>(beams), range);
    grid.insertScan(RangeScan{ranges, 0.0, 0.0, 0.1, 8.0}, Pose2(0.01, 0.01, 0.0));
  };
  const Eigen::Vector2i c(20, 0);
  repeat(1.0f, 40);
  const double low = grid.cellCenter(c).x() - 0.3 * 0.05;
  CHECK(grid.hitPoint(c).x() == Approx(low).margin(1.0 / 256 * 0.05));
  CHECK(grid.hitCount(c) == 40);
  repeat(1.03f, 1);  // weight 1/32, not 1/41
  CHECK(grid.hitPoint(c).x() == Approx(low + 0.6 * 0.05 / 32).margin(1.5 / 256 * 0.05));
  CHECK(grid.hitPoint(c).y() ==
        Approx(grid.cellCenter(c).y() - 0.3 * 0.05).margin(0.5 / 256 * 0.05));
  repeat(1.03f, 300);
  CHECK(grid.hitCount(c) == 255);
  // Settled within one storage step of the new position, not left 1/16 cell short.
  CHECK(grid.hitPoint(c).x() == Approx(low + 0.6 * 0.05).margin(1.0 / 256 * 0.05));
}

TEST_CASE("untracked TiledGrid tiles keep their size and tracked tiles add 3 bytes a cell",
          "[tiled_grid]") {
  constexpr std::size_t kCells = TiledGrid::kTileCells;
  // Cells, the count (padded to 8 bytes), the occupancy cache's key and one bit per cell.
  CHECK(TiledGrid::tileBytes() ==
        kCells * sizeof(std::int16_t) + 8 + sizeof(std::uint64_t) + kCells / 8);
  CHECK(TiledGrid::tileBytes(false) == TiledGrid::tileBytes());
  CHECK(TiledGrid::tileBytes(true) == TiledGrid::tileBytes() + 3 * kCells);
  TiledGrid plain(tiledOptions(0.05)), tracked(trackedOptions(0.05));
  const auto scans = roomScans(9, 3);
  insertRoom(plain, scans);
  insertRoom(tracked, scans);
  REQUIRE(plain.tileCount() == tracked.tileCount());
  CHECK(tracked.memoryBytes() - plain.memoryBytes() == 3 * kCells * tracked.tileCount());
}

TEST_CASE("copies of a tracked TiledGrid share hit points and a write clones them",
          "[tiled_grid]") {
  TiledGrid original(trackedOptions(0.05));
  insertRoom(original, roomScans(13, 6));
  TiledGrid snapshot(original.options());
  insertRoom(snapshot, roomScans(13, 6));
  REQUIRE(sameHits(original, snapshot));

  auto before = TiledGrid::counters();
  TiledGrid copy(original);
  CHECK(countersSince(before).tiles_cloned == 0);
  CHECK(copy.tracksHitPoints());
  CHECK(sameHits(copy, original));

  // The copy sees one more scan: its own grid must equal a grid built with all the scans, and
  // the original must not notice.
  const auto extra = roomScans(14, 1);
  before = TiledGrid::counters();
  insertRoom(copy, extra);
  CHECK(countersSince(before).tiles_cloned > 0);
  CHECK(sameHits(original, snapshot));
  TiledGrid expected(original.options());
  insertRoom(expected, roomScans(13, 6));
  insertRoom(expected, extra);
  CHECK(sameHits(copy, expected));
  CHECK_FALSE(sameHits(copy, original));

  SECTION("assignment and moves keep the hit points") {
    TiledGrid assigned(tiledOptions(0.1));  // untracked until assigned
    assigned = copy;
    CHECK(assigned.tracksHitPoints());
    CHECK(sameHits(assigned, expected));
    TiledGrid moved(std::move(assigned));
    CHECK(sameHits(moved, expected));
    TiledGrid target(tiledOptions(0.05));
    insertRoom(target, extra);  // untracked tiles, released as such
    target = std::move(moved);
    CHECK(sameHits(target, expected));
  }
}

TEST_CASE("concurrent writes to tracked TiledGrid copies match serially built grids",
          "[tiled_grid]") {
  checkConcurrentCopies(trackedOptions(0.05), roomScans, 4, 3, insertRoom, sameHits);
}

namespace {
/// Every bit of occupancyRows() over random windows (across tile borders, outside the table,
/// negative cells) equals logOdds(c) > threshold.
bool occupancyRowsMatchCells(const TiledGrid& grid, float threshold, unsigned seed) {
  std::mt19937 rng(seed);
  const CellBox& known = grid.knownBounds();
  std::uniform_int_distribution<int> x(known.min.x() - 40, known.max.x() + 8);
  std::uniform_int_distribution<int> y(known.min.y() - 40, known.max.y() + 8);
  std::uniform_int_distribution<int> height(1, 70);
  for (int k = 0; k < 300; ++k) {
    const int x0 = x(rng), y0 = y(rng), h = height(rng);
    std::vector<std::uint32_t> rows(static_cast<std::size_t>(h));
    grid.occupancyRows(x0, y0, h, threshold, rows.data());
    for (int i = 0; i < h; ++i)
      for (int j = 0; j < 32; ++j) {
        const bool bit = ((rows[static_cast<std::size_t>(i)] >> j) & 1u) != 0;
        if (bit != (grid.logOdds({x0 + j, y0 + i}) > threshold)) return false;
      }
  }
  return true;
}
}  // namespace

TEST_CASE("TiledGrid occupancy rows follow the cells through updates and copies",
          "[tiled_grid][occupancy_rows]") {
  TiledGrid grid(tiledOptions(0.05));
  insertAll(grid, randomScans(31, 12, {0.0, 0.0}, 2.0));
  // Thresholds alternate on the same tiles: each tile caches one, the other is computed.
  // Also thresholds on a fixed-point step (0.5 = 512/1024), at −0, and beyond the stored range
  // (nothing or every known cell above; unknown cells read 0).
  for (float threshold : {0.0f, 0.5f, -0.3f, 0.0f, -0.0f, 40.0f, -40.0f,
                          std::numeric_limits<float>::infinity(), -1e-6f}) {
    INFO("threshold " << threshold);
    CHECK(occupancyRowsMatchCells(grid, threshold, 1));
  }

  SECTION("after more scans into the same grid") {
    insertAll(grid, randomScans(32, 6, {0.5, -0.5}, 2.0));
    for (float threshold : {0.0f, -0.3f}) CHECK(occupancyRowsMatchCells(grid, threshold, 2));
  }
  SECTION("after a write to a copy: the copy sees it, the original does not") {
    TiledGrid copy = grid;
    const std::size_t tiles_before = grid.uniqueTileCount();
    insertAll(copy, randomScans(33, 4, {0.2, 0.3}, 1.0));
    REQUIRE_FALSE(sameCells(copy, grid));
    CHECK(occupancyRowsMatchCells(copy, 0.0f, 3));
    CHECK(occupancyRowsMatchCells(grid, 0.0f, 3));
    CHECK(grid.uniqueTileCount() > tiles_before);  // the copy cloned what it wrote
  }
  SECTION("a change in one tile shows in windows read from its neighbour") {
    // Fill the caches, then hit the first cell of a tile with a ray that stays in that tile:
    // its left neighbour's cells (and cached bits) stay as they were.
    CHECK(occupancyRowsMatchCells(grid, 0.0f, 4));
    const Eigen::Vector2i target(2 * TiledGrid::kTileSide, -3 * TiledGrid::kTileSide + 5);
    const Eigen::Vector2d at = grid.cellCenter(target);
    const std::vector<float> range{0.3f};
    const Pose2 sensor(at.x() + 0.3, at.y(),
                       std::numbers::pi);  // looks along −x onto the border cell
    const RangeScan one{range, 0.0, 0.0, 0.1, 8.0};
    for (int k = 0; k < 5; ++k) grid.insertScan(one, sensor, kInsert);
    REQUIRE(grid.logOdds(target) > 0.0f);
    std::uint32_t row = 0;
    grid.occupancyRows(target.x() - 20, target.y(), 1, 0.0f, &row);  // mostly the left tile
    CHECK(((row >> 20) & 1u) == 1u);
    CHECK(occupancyRowsMatchCells(grid, 0.0f, 5));
  }
}

TEST_CASE("concurrent occupancy rows on copies sharing tiles equal the cells",
          "[tiled_grid][occupancy_rows]") {
  TiledGrid base(tiledOptions(0.05));
  insertAll(base, randomScans(41, 10, {0.0, 0.0}, 2.0));
  // Copies share every tile, and none has a cache yet: threads race to fill the same tiles,
  // with different thresholds.
  std::vector<TiledGrid> copies(4, base);
  std::vector<int> ok(copies.size(), 0);
  std::vector<std::thread> threads;
  for (std::size_t i = 0; i < copies.size(); ++i)
    threads.emplace_back([&, i] {
      ok[i] =
          occupancyRowsMatchCells(copies[i], i % 2 == 0 ? 0.0f : 0.7f, static_cast<unsigned>(i));
    });
  for (auto& t : threads) t.join();
  for (std::size_t i = 0; i < copies.size(); ++i) CHECK(ok[i] == 1);
  CHECK(occupancyRowsMatchCells(base, 0.7f, 9));
}
