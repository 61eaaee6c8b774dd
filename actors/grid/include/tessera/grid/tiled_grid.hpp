// TiledGrid: a copy-on-write, tiled log-odds occupancy grid for particle filters
// (Rao-Blackwellised SLAM: every particle owns a map and resampling copies particles).
//
// Same model, frame, units and cell convention as OccupancyGrid (occupancy_grid.hpp): absolute
// cell indices, cell (i, j) covers [i·res, (i+1)·res) × [j·res, (j+1)·res) in metres, and
// insertScan() produces the same cells (both grids share one ray rasteriser), up to fixed-point
// quantisation of the log-odds.
//
// Storage: cells live in 32×32-cell tiles of int16 fixed-point log-odds (round(L·1024), clamped
// to the model's bounds; INT16_MIN = unknown), 2 KiB of cells per tile. A dense table over the
// box of tiles seen so far points at the tiles; absent tiles are unknown and cost one pointer.
// Tiles are reference counted and shared: copying a grid copies only the table and bumps the
// counts, so N particles that resample from one cost ~1× the map, not N×. A write to a shared
// tile first clones it (copy-on-write); a write to an absent tile allocates it; reads never
// allocate. Memory therefore grows with the explored area plus what each particle has changed.
// The table grows by whole tiles with a margin, up to max_side_cells per axis (rounded down to
// whole tiles, at least one); updates beyond it are dropped and counted (clipped_cells).
//
// Hit points (opt-in, track_hit_points): each cell also keeps the running mean of the beam
// endpoints that hit it, as GMapping does, so a scan matcher can measure distances to where the
// wall actually is instead of to the cell centre (which quantises walls to the cell size). A
// tracked tile adds 3 bytes per cell (int8 x/y offsets from the cell centre in resolution/256
// units, a saturating uint8 count); untracked grids keep the plain 2 KiB tiles.
//
// Occupancy bits (occupancyRows()): the scan matcher asks which cells are above its occupied
// threshold thousands of times per update. Each tile caches that as 32 rows of 32 bits, built
// lazily on the first request after the tile changed and shared with the tile, so particles
// that share a tile share its bits too. The bits depend only on the tile's own cells, so a write
// (which always goes to a tile this grid alone holds) simply drops that tile's bits; no
// neighbouring tile is ever affected. One threshold is cached per tile; a request with another
// threshold is answered from a temporary copy. Cost: 136 bytes per tile (about 7 %).
//
// Thread safety: distinct TiledGrid objects may be written concurrently from different threads
// even when they share tiles (e.g. particles updated in parallel with TBB after resampling):
// reference counts are atomic and a tile referenced by more than one grid is never written in
// place. One object must not be written by two threads at once, nor copied while written;
// const methods may run concurrently on one object. Scan rasterisation uses per-thread scratch.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>
#include <tessera/grid/occupancy_map.hpp>

#include <Eigen/Core>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

namespace tessera::grid {
namespace detail {
class ScanRasterizer;
}

struct TiledGridOptions {
  double resolution = 0.05;  ///< [m/cell]
  /// Log-odds model; bounds must lie within ±31.99 and increments be ≥ 1/1024 in magnitude
  /// (the fixed-point range and step).
  LogOddsModel log_odds;
  /// Per-axis limit of the tile table [cells], rounded down to whole tiles (at least one);
  /// updates beyond it are dropped and counted in ScanInsertResult::clipped_cells.
  int max_side_cells = 16384;
  /// Keep per cell the mean position of the beam endpoints that hit it (see hitPoint()). Each
  /// hit moves the mean by 1/min(hits, 32) of the way to the endpoint, so it averages the first
  /// 32 hits exactly (up to the 1/256-cell storage step) and then follows slowly, like a moving
  /// average over ~32 hits (stepping at least 1/256 cell towards a differing endpoint, so it
  /// settles within that of a steady wall). Costs 2.5× the tile memory and a little insert
  /// time. Off by default.
  bool track_hit_points = false;

  template <class V>
  void visit(V& v) {
    v("resolution", resolution, "cell size [m]");
    v("log_odds", log_odds, "log-odds model");
    v("max_side_cells", max_side_cells,
      "tile table limit per axis [cells]; updates beyond it are dropped");
    v("track_hit_points", track_hit_points,
      "keep each cell's mean hit position and match against it (sub-cell accuracy, 2.5x tile "
      "memory)");
  }
};

class TiledGrid {
 public:
  using Options = TiledGridOptions;
  static constexpr int kTileBits = 5;  ///< 32×32 cells per tile
  static constexpr int kTileSide = 1 << kTileBits;
  static constexpr int kTileCells = kTileSide * kTileSide;
  /// Fixed-point scale of the stored log-odds: one unit is 1/1024 of a log-odds.
  static constexpr float kLogOddsScale = 1024.0f;
  /// Fixed-point scale of the stored hit offsets: one unit is 1/256 of a cell.
  static constexpr float kHitScale = 256.0f;
  /// Hits after which the mean hit position stops being a plain average (see the option).
  static constexpr int kHitWindow = 32;

  /// Throws std::invalid_argument for a non-positive resolution or limit, inconsistent
  /// log-odds signs (as OccupancyGrid), or a model outside the fixed-point range.
  explicit TiledGrid(Options options = {});
  ~TiledGrid();
  /// O(table size): shares every tile, copies no cells.
  TiledGrid(const TiledGrid& other);
  TiledGrid& operator=(const TiledGrid& other);
  /// The moved-from grid is left empty (no tiles, nothing known).
  TiledGrid(TiledGrid&& other) noexcept;
  TiledGrid& operator=(TiledGrid&& other) noexcept;

  const Options& options() const { return options_; }
  double resolution() const { return options_.resolution; }

  /// The cell containing map-frame point p.
  Eigen::Vector2i worldToCell(const Eigen::Vector2d& p) const;
  /// Centre of cell c [m].
  Eigen::Vector2d cellCenter(const Eigen::Vector2i& c) const;
  /// Lower-left (outer) corner of cell c [m].
  Eigen::Vector2d cellCorner(const Eigen::Vector2i& c) const;

  bool isKnown(const Eigen::Vector2i& c) const {
    const Tile* t = tileAt(c);
    return t != nullptr && t->cells[cellInTile(c)] != kUnknown;
  }
  /// Log-odds of c; 0 (S_init) for unknown cells and cells outside the grid. The scan
  /// matcher's hot path: a bounds check, one table lookup and one index, all inline.
  float logOdds(const Eigen::Vector2i& c) const {
    const Tile* t = tileAt(c);
    if (t == nullptr) return 0.0f;
    const std::int16_t v = t->cells[cellInTile(c)];
    return v == kUnknown ? 0.0f : static_cast<float>(v) * (1.0f / kLogOddsScale);
  }
  /// Occupancy probability of c; 0.5 when unknown.
  double probability(const Eigen::Vector2i& c) const;

  bool tracksHitPoints() const { return options_.track_hit_points; }
  /// Mean position [m] of the beam endpoints that hit c; the cell centre when c has no hits or
  /// the grid does not track them. Always inside c (offsets are within [−½, ½) cell). Inline
  /// for the scan matcher's hot path.
  Eigen::Vector2d hitPoint(const Eigen::Vector2i& c) const {
    const double res = options_.resolution;
    Eigen::Vector2d p((c.x() + 0.5) * res, (c.y() + 0.5) * res);
    if (!options_.track_hit_points) return p;
    const Tile* t = tileAt(c);
    if (t == nullptr) return p;
    // A cell without hits holds zero offsets, so no separate test of the count is needed.
    const HitCell& h = static_cast<const TrackedTile*>(t)->hits[cellInTile(c)];
    const double scale = res * (1.0 / kHitScale);
    p.x() += h.dx * scale;
    p.y() += h.dy * scale;
    return p;
  }
  /// Endpoints that have hit c, saturating at 255; 0 when the grid does not track them.
  int hitCount(const Eigen::Vector2i& c) const {
    if (!options_.track_hit_points) return 0;
    const Tile* t = tileAt(c);
    return t == nullptr ? 0 : static_cast<const TrackedTile*>(t)->hits[cellInTile(c)].count;
  }

  /// Occupancy bits of a window 32 cells wide: bit j of rows[i] is set when
  /// logOdds({x0 + j, y0 + i}) > threshold, for i in [0, height). Exactly that predicate,
  /// unknown and outside cells included (they read 0). Fills the tiles' caches on the way (see
  /// the header comment); safe to call concurrently on one grid and on grids sharing tiles.
  /// Inline: this is the scan matcher's hot path (a few times per beam per pose).
  void occupancyRows(int x0, int y0, int height, float threshold, std::uint32_t* rows) const {
    const std::uint64_t key = occupancyKey(threshold);
    const unsigned shift = static_cast<unsigned>(x0) & (kTileSide - 1);
    // The window spans at most two tile columns; take it one tile row at a time. Every source
    // is a row array (absent tiles read constant rows), so the row loop has no branches.
    for (int i = 0; i < height;) {
      const int y = y0 + i;
      const int first = y & (kTileSide - 1);
      const int run = std::min(height - i, kTileSide - first);
      const std::atomic<std::uint32_t>* src[2];
      for (int k = 0; k < 2; ++k) {
        const Tile* t = tileAt({x0 + k * kTileSide, y});
        if (t == nullptr)
          src[k] = 0.0f > threshold ? kAllOccupied : kNoneOccupied;  // as logOdds(): 0
        else if (t->occ_key.load(std::memory_order_acquire) == key)
          src[k] = t->occ_rows;
        else
          src[k] = occupancySlow(*t, threshold, k);
      }
      for (int r = first; r < first + run; ++r, ++i) {
        const std::uint64_t left = src[0][r].load(std::memory_order_relaxed);
        const std::uint64_t right = src[1][r].load(std::memory_order_relaxed);
        rows[i] = static_cast<std::uint32_t>((left | (right << kTileSide)) >> shift);
      }
    }
  }

  /// Smallest box holding every cell updated at least once (empty before the first update).
  const CellBox& knownBounds() const { return known_bounds_; }
  /// Number of cells updated at least once.
  std::size_t knownCount() const { return known_count_; }

  /// Integrates one scan taken from `sensor_pose`; same semantics and cells as
  /// OccupancyGrid::insertScan (once per scan per cell, a hit wins over a miss, no-return
  /// beams clear up to max_free_range). Never throws on bad data: NaN/negative ranges, an
  /// empty scan or a non-finite pose are counted and leave the grid untouched.
  ScanInsertResult insertScan(const RangeScan& scan, const Pose2& sensor_pose,
                              const ScanInsertOptions& insert_options = {});

  /// Writes ROS int8 cells for `box` into `out` (box.width()·box.height() values, row-major,
  /// row 0 = box.min.y); unknown cells are −1. Throws std::invalid_argument on a size mismatch.
  void exportInt8(const CellBox& box, std::span<std::int8_t> out) const;
  /// The grid as a ROS-convention map cropped to `box` (default: the known cells).
  OccupancyMap toOccupancyMap() const { return toOccupancyMap(known_bounds_); }
  OccupancyMap toOccupancyMap(const CellBox& box) const;

  /// Tiles referenced by this grid.
  std::size_t tileCount() const;
  /// Tiles referenced only by this grid (what it alone keeps alive).
  std::size_t uniqueTileCount() const;
  /// Bytes of cell storage this grid references: its tiles (shared or not) plus its table.
  std::size_t memoryBytes() const;
  /// This grid's share of the cell storage: each tile's bytes divided among the grids holding
  /// it, plus its table. Summed over every grid that holds a set of tiles (a particle filter's
  /// maps), it gives the bytes they hold together, each shared tile counted once.
  double sharedMemoryBytes() const;
  /// Bytes of one tile (cells, reference count and, when tracked, the hit points).
  static std::size_t tileBytes(bool track_hit_points = false) {
    return track_hit_points ? sizeof(TrackedTile) : sizeof(Tile);
  }

  /// Process-wide totals since start (relaxed atomics), for tests and benchmarks.
  struct Counters {
    std::uint64_t tiles_allocated = 0;  ///< absent tiles created by a write
    std::uint64_t tiles_cloned = 0;     ///< shared tiles copied by a write
  };
  static Counters counters();

 private:
  static constexpr std::int16_t kUnknown = std::numeric_limits<std::int16_t>::min();

  struct Tile {
    std::int16_t cells[kTileCells];
    std::atomic<std::uint32_t> refs{1};
    // Occupancy bit cache (occupancyRows()): occ_key says for which threshold occ_rows hold,
    // 0 = stale. Atomics because grids sharing the tile may fill it concurrently.
    mutable std::atomic<std::uint64_t> occ_key{0};
    mutable std::atomic<std::uint32_t> occ_rows[kTileSide] = {};
  };
  struct HitCell {
    std::int8_t dx = 0, dy = 0;  // mean hit offset from the cell centre [cell/kHitScale]
    std::uint8_t count = 0;      // hits so far, saturating
  };
  // A tracked grid allocates only these; the grid's option says which type its tiles are, so
  // the plain Tile needs no virtual destructor or type tag and keeps its size.
  struct TrackedTile : Tile {
    HitCell hits[kTileCells];
  };

  static int cellInTile(const Eigen::Vector2i& c) {
    return ((c.y() & (kTileSide - 1)) << kTileBits) | (c.x() & (kTileSide - 1));
  }
  /// Table slot of the tile holding c, or −1 outside the table.
  long slotOf(const Eigen::Vector2i& c) const {
    // Unsigned compare folds the < 0 and ≥ size checks into one.
    const auto tx = static_cast<unsigned>((c.x() >> kTileBits) - tiles_.min.x());
    const auto ty = static_cast<unsigned>((c.y() >> kTileBits) - tiles_.min.y());
    if (tx >= tiles_w_ || ty >= tiles_h_) return -1;
    return static_cast<long>(ty) * tiles_w_ + tx;
  }
  const Tile* tileAt(const Eigen::Vector2i& c) const {
    const long s = slotOf(c);
    return s < 0 ? nullptr : table_[static_cast<std::size_t>(s)];
  }
  /// The tile at `slot`, allocated if absent and cloned if shared, so it can be written.
  Tile* writableTile(std::size_t slot);
  // occ_key values: 0 = stale, kFilling = a thread is filling the rows, else kValid | the
  // threshold's bits.
  static constexpr std::uint64_t kFilling = 1;
  static constexpr std::uint64_t kValid = std::uint64_t{1} << 32;
  static std::uint64_t occupancyKey(float threshold) {
    return kValid | std::bit_cast<std::uint32_t>(threshold);
  }
  static const std::atomic<std::uint32_t> kNoneOccupied[kTileSide];
  static const std::atomic<std::uint32_t> kAllOccupied[kTileSide];
  /// t's occupancy rows when its cache is not valid for `threshold`: fills the cache when it
  /// is stale and free, else computes them into per-thread scratch number `which` (0 or 1),
  /// valid until the next call with that number (the cache holds another threshold or another
  /// thread is filling it).
  static const std::atomic<std::uint32_t>* occupancySlow(const Tile& t, float threshold, int which);
  /// Drops this grid's reference to t, deleting it (as the grid's tile type) if it was the last.
  void releaseTile(Tile* t) noexcept;
  /// Folds the scan's hit endpoints into the tiles' mean hit positions.
  void updateHitPoints(const detail::ScanRasterizer& rasterizer);
  /// Grows the table so the tiles of `need` fit where the limit allows.
  void growToInclude(const CellBox& need, const Eigen::Vector2i& anchor);
  void releaseAll() noexcept;

  Options options_;
  // Fixed-point model: increments and clamp bounds in 1/kLogOddsScale units.
  std::int32_t q_hit_ = 0, q_miss_ = 0, q_min_ = 0, q_max_ = 0;
  CellBox known_bounds_;
  std::size_t known_count_ = 0;
  CellBox tiles_;  // box of tile indices the table covers (tile (u, v) holds cells 32u.., 32v..)
  unsigned tiles_w_ = 0, tiles_h_ = 0;
  std::vector<Tile*> table_;  // row-major over tiles_; nullptr = absent (all unknown)
};

}  // namespace tessera::grid
