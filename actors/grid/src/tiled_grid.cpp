#include <tessera/grid/tiled_grid.hpp>

#include "scan_rasterizer.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace tessera::grid {
namespace {

std::atomic<std::uint64_t> g_tiles_allocated{0};
std::atomic<std::uint64_t> g_tiles_cloned{0};

// Growing the table costs a pass over it, so it grows by at least this many tiles (or a
// quarter of its extent) on each side that needs room.
constexpr int kMinMarginTiles = 2;

std::int32_t quantize(float log_odds) {
  return static_cast<std::int32_t>(std::lround(log_odds * TiledGrid::kLogOddsScale));
}

Eigen::Vector2i tileOf(const Eigen::Vector2i& c) {
  return {c.x() >> TiledGrid::kTileBits, c.y() >> TiledGrid::kTileBits};
}

}  // namespace

TiledGrid::TiledGrid(Options options) : options_(options) {
  const auto& l = options_.log_odds;
  detail::checkGridOptions(options_.resolution, l, options_.max_side_cells, "TiledGrid");
  const bool finite =
      std::isfinite(l.hit) && std::isfinite(l.miss) && std::isfinite(l.min) && std::isfinite(l.max);
  const float lim = static_cast<float>(std::numeric_limits<std::int16_t>::max()) / kLogOddsScale;
  if (!finite || l.max > lim || l.min < -lim || l.hit > lim || l.miss < -lim)
    throw std::invalid_argument("TiledGrid: log-odds must lie within ±" + std::to_string(lim) +
                                " (int16 fixed point)");
  q_hit_ = quantize(l.hit);
  q_miss_ = quantize(l.miss);
  q_min_ = quantize(l.min);
  q_max_ = quantize(l.max);
  if (q_hit_ < 1 || q_miss_ > -1 || q_min_ > -1 || q_max_ < 1)
    throw std::invalid_argument("TiledGrid: log-odds increments and bounds must be at least " +
                                std::to_string(1.0f / kLogOddsScale) + " in magnitude");
}

TiledGrid::~TiledGrid() {
  releaseAll();
}

TiledGrid::TiledGrid(const TiledGrid& other)
    : options_(other.options_),
      q_hit_(other.q_hit_),
      q_miss_(other.q_miss_),
      q_min_(other.q_min_),
      q_max_(other.q_max_),
      known_bounds_(other.known_bounds_),
      known_count_(other.known_count_),
      tiles_(other.tiles_),
      tiles_w_(other.tiles_w_),
      tiles_h_(other.tiles_h_),
      table_(other.table_) {
  // Relaxed is enough for an increment: the caller already holds a reference (through other).
  for (Tile* t : table_)
    if (t != nullptr) t->refs.fetch_add(1, std::memory_order_relaxed);
}

TiledGrid& TiledGrid::operator=(const TiledGrid& other) {
  if (this != &other) *this = TiledGrid(other);
  return *this;
}

TiledGrid::TiledGrid(TiledGrid&& other) noexcept
    : options_(other.options_),
      q_hit_(other.q_hit_),
      q_miss_(other.q_miss_),
      q_min_(other.q_min_),
      q_max_(other.q_max_),
      known_bounds_(std::exchange(other.known_bounds_, CellBox{})),
      known_count_(std::exchange(other.known_count_, 0)),
      tiles_(std::exchange(other.tiles_, CellBox{})),
      tiles_w_(std::exchange(other.tiles_w_, 0u)),
      tiles_h_(std::exchange(other.tiles_h_, 0u)),
      table_(std::exchange(other.table_, {})) {}

TiledGrid& TiledGrid::operator=(TiledGrid&& other) noexcept {
  if (this == &other) return *this;
  releaseAll();
  options_ = other.options_;
  q_hit_ = other.q_hit_;
  q_miss_ = other.q_miss_;
  q_min_ = other.q_min_;
  q_max_ = other.q_max_;
  known_bounds_ = std::exchange(other.known_bounds_, CellBox{});
  known_count_ = std::exchange(other.known_count_, 0);
  tiles_ = std::exchange(other.tiles_, CellBox{});
  tiles_w_ = std::exchange(other.tiles_w_, 0u);
  tiles_h_ = std::exchange(other.tiles_h_, 0u);
  table_ = std::exchange(other.table_, {});
  return *this;
}

void TiledGrid::releaseTile(Tile* t) noexcept {
  // acq_rel: the last owner must see every other owner's reads done before it deletes.
  if (t->refs.fetch_sub(1, std::memory_order_acq_rel) != 1) return;
  if (options_.track_hit_points)
    delete static_cast<TrackedTile*>(t);
  else
    delete t;
}

void TiledGrid::releaseAll() noexcept {
  for (Tile*& t : table_) {
    if (t != nullptr) releaseTile(t);
    t = nullptr;
  }
  table_.clear();
}

Eigen::Vector2i TiledGrid::worldToCell(const Eigen::Vector2d& p) const {
  return detail::cellOf(p, options_.resolution);
}

Eigen::Vector2d TiledGrid::cellCenter(const Eigen::Vector2i& c) const {
  return detail::cellCenterOf(c, options_.resolution);
}

Eigen::Vector2d TiledGrid::cellCorner(const Eigen::Vector2i& c) const {
  return detail::cellCornerOf(c, options_.resolution);
}

double TiledGrid::probability(const Eigen::Vector2i& c) const {
  return detail::probabilityOf(logOdds(c));
}

TiledGrid::Tile* TiledGrid::writableTile(std::size_t slot) {
  Tile*& t = table_[slot];
  const bool tracked = options_.track_hit_points;
  if (t == nullptr) {
    t = tracked ? new TrackedTile : new Tile;  // TrackedTile's hits start at zero (no hits)
    std::fill(std::begin(t->cells), std::end(t->cells), kUnknown);
    g_tiles_allocated.fetch_add(1, std::memory_order_relaxed);
  } else if (t->refs.load(std::memory_order_acquire) == 1) {
    // Written in place: its occupancy bits go stale. Nobody else can be reading them (the
    // tile is this grid's alone and a grid is not read while written).
    t->occ_key.store(0, std::memory_order_relaxed);
  } else {
    // Shared: clone, then drop our reference. Acquire pairs with the release in another
    // grid's drop, so when the count reads 1 that grid's reads of the tile are finished and
    // writing in place is safe.
    Tile* copy;
    if (tracked) {
      auto* tracked_copy = new TrackedTile;
      const auto* source = static_cast<const TrackedTile*>(t);
      std::copy(std::begin(source->hits), std::end(source->hits), std::begin(tracked_copy->hits));
      copy = tracked_copy;
    } else {
      copy = new Tile;
    }
    std::copy(std::begin(t->cells), std::end(t->cells), std::begin(copy->cells));
    releaseTile(t);
    t = copy;
    g_tiles_cloned.fetch_add(1, std::memory_order_relaxed);
  }
  return t;
}

void TiledGrid::growToInclude(const CellBox& need, const Eigen::Vector2i& anchor) {
  const CellBox need_tiles{tileOf(need.min), tileOf(need.max)};
  const Eigen::Vector2i anchor_tile = tileOf(anchor);
  const int limit = std::max(1, options_.max_side_cells / kTileSide);
  const CellBox fit = detail::growBox(tiles_, need_tiles, anchor_tile, 1, limit);
  if (!tiles_.empty() && fit.min == tiles_.min && fit.max == tiles_.max) return;
  // Pad the sides that grew; growBox keeps `fit` whole and only gives the padding the room
  // left under the limit.
  CellBox padded = fit;
  for (int axis = 0; axis < 2; ++axis) {
    const int margin = std::max(kMinMarginTiles, (fit.max[axis] - fit.min[axis] + 1) / 4);
    if (tiles_.empty() || fit.min[axis] < tiles_.min[axis]) padded.min[axis] -= margin;
    if (tiles_.empty() || fit.max[axis] > tiles_.max[axis]) padded.max[axis] += margin;
  }
  const CellBox target = detail::growBox(fit, padded, anchor_tile, 1, limit);

  const auto w = static_cast<std::size_t>(target.width());
  std::vector<Tile*> table(w * static_cast<std::size_t>(target.height()), nullptr);
  for (unsigned v = 0; v < tiles_h_; ++v) {
    const std::size_t dst = static_cast<std::size_t>(tiles_.min.y() + v - target.min.y()) * w +
                            static_cast<std::size_t>(tiles_.min.x() - target.min.x());
    std::copy_n(table_.begin() + static_cast<long>(v) * tiles_w_, tiles_w_, table.begin() + dst);
  }
  table_ = std::move(table);  // pointers moved, not released: reference counts are unchanged
  tiles_ = target;
  tiles_w_ = static_cast<unsigned>(target.width());
  tiles_h_ = static_cast<unsigned>(target.height());
}

ScanInsertResult TiledGrid::insertScan(const RangeScan& scan, const Pose2& sensor_pose,
                                       const ScanInsertOptions& insert_options) {
  auto& rasterizer = detail::ScanRasterizer::forThisThread();
  ScanInsertResult result =
      rasterizer.classify(scan, sensor_pose, insert_options, options_.resolution);
  if (!rasterizer.hasBeams()) return result;
  growToInclude(rasterizer.need(), rasterizer.originCell());
  rasterizer.collect(
      {tiles_.min * kTileSide, tiles_.max * kTileSide + Eigen::Vector2i::Constant(kTileSide - 1)},
      result, options_.track_hit_points);

  // Updates come in ray order, so runs of cells share a tile: look it up once per run.
  long current_slot = -1;
  Tile* tile = nullptr;
  for (const detail::CellUpdate& u : rasterizer.updates()) {
    const long slot = slotOf(u.cell);  // inside the table: collect() clipped the rest
    if (slot != current_slot) {
      tile = writableTile(static_cast<std::size_t>(slot));
      current_slot = slot;
    }
    std::int16_t& v = tile->cells[cellInTile(u.cell)];
    std::int32_t old = v;
    if (v == kUnknown) {
      old = 0;
      ++known_count_;
      known_bounds_.extend(u.cell);
    }
    v = static_cast<std::int16_t>(std::clamp(old + (u.hit ? q_hit_ : q_miss_), q_min_, q_max_));
  }
  if (options_.track_hit_points) updateHitPoints(rasterizer);
  return result;
}

void TiledGrid::updateHitPoints(const detail::ScanRasterizer& rasterizer) {
  long current_slot = -1;
  TrackedTile* tile = nullptr;
  for (const detail::HitPoint& h : rasterizer.hitPoints()) {
    // Hit cells were just written above, so their tiles are already this grid's own.
    const long slot = slotOf(h.cell);
    if (slot != current_slot) {
      tile = static_cast<TrackedTile*>(writableTile(static_cast<std::size_t>(slot)));
      current_slot = slot;
    }
    HitCell& cell = tile->hits[cellInTile(h.cell)];
    if (cell.count < std::numeric_limits<std::uint8_t>::max()) ++cell.count;
    const float weight = 1.0f / static_cast<float>(std::min<int>(cell.count, kHitWindow));
    // Past the window a rounded 1/32 step is zero for targets within 16 storage steps, which
    // would freeze the mean up to 1/16 cell away from a steady wall; a minimum step of one
    // lets it settle within one storage step instead. Inside the window plain rounding keeps
    // the mean an average.
    const bool settling = cell.count > kHitWindow;
    auto blend = [weight, settling](std::int8_t mean, float target) {
      const float diff = target * kHitScale - static_cast<float>(mean);
      long step = std::lround(diff * weight);
      if (step == 0 && settling && std::abs(diff) >= 1.0f) step = diff > 0.0f ? 1 : -1;
      // The int8 range covers [−½, ½) cell; an endpoint at the upper edge rounds to 128.
      return static_cast<std::int8_t>(std::clamp(mean + step, -128L, 127L));
    };
    cell.dx = blend(cell.dx, h.offset.x());
    cell.dy = blend(cell.dy, h.offset.y());
  }
}

namespace {
/// The occupancy predicate of occupancyRows() in fixed point: a known cell v is above
/// `threshold` iff v > above, and an unknown one (read as 0) iff unknown_occupied.
struct FixedThreshold {
  std::int16_t above;
  bool unknown_occupied;
};
FixedThreshold fixedThreshold(float threshold) {
  // v·(1/1024) is exact in float for every int16 v, so logOdds > threshold is the exact
  // comparison v > 1024·threshold (exact in double), i.e. v > floor(1024·threshold) for
  // integers; clamped, a bound beyond the int16 range keeps its meaning.
  const double bound = std::floor(static_cast<double>(threshold) * TiledGrid::kLogOddsScale);
  const double lo = std::numeric_limits<std::int16_t>::min();
  const double hi = std::numeric_limits<std::int16_t>::max();
  if (std::isnan(bound)) return {std::numeric_limits<std::int16_t>::max(), false};  // never above
  return {static_cast<std::int16_t>(std::clamp(bound, lo, hi)), 0.0f > threshold};
}

/// Row `row` of the occupancy bits of `cells` (one tile): bit x set iff logOdds of cell x of
/// the row > threshold (the same predicate as logOdds(c) > threshold, exactly).
std::uint32_t occupancyRowOf(const std::int16_t* cells, int row, FixedThreshold t,
                             std::int16_t unknown) {
  cells += row * TiledGrid::kTileSide;
#if defined(__SSE2__)
  // Eight cells per compare; packing the 16-bit masks to bytes keeps their order, so byte
  // masks of 16 cells are 16 consecutive bits.
  const __m128i above = _mm_set1_epi16(t.above);
  const __m128i unknown_v = _mm_set1_epi16(unknown);
  auto mask8 = [&](int k) {
    const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(cells + 8 * k));
    const __m128i gt = _mm_cmpgt_epi16(v, above);
    const __m128i unk = _mm_cmpeq_epi16(v, unknown_v);
    // The unknown value is the int16 minimum, which is never above a bound ≥ that minimum, so
    // only the occupied-unknown case needs the mask.
    return t.unknown_occupied ? _mm_or_si128(gt, unk) : gt;
  };
  const auto low =
      static_cast<std::uint32_t>(_mm_movemask_epi8(_mm_packs_epi16(mask8(0), mask8(1))));
  const auto high =
      static_cast<std::uint32_t>(_mm_movemask_epi8(_mm_packs_epi16(mask8(2), mask8(3))));
  static_assert(TiledGrid::kTileSide == 32);
  return low | (high << 16);
#else
  std::uint32_t bits = 0;
  for (int x = 0; x < TiledGrid::kTileSide; ++x) {
    const std::int16_t v = cells[x];
    const bool occupied = v == unknown ? t.unknown_occupied : v > t.above;
    bits |= static_cast<std::uint32_t>(occupied) << x;
  }
  return bits;
#endif
}
}  // namespace

const std::atomic<std::uint32_t> TiledGrid::kNoneOccupied[kTileSide] = {};
const std::atomic<std::uint32_t> TiledGrid::kAllOccupied[kTileSide] = {
    ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u,
    ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u, ~0u};

const std::atomic<std::uint32_t>* TiledGrid::occupancySlow(const Tile& t, float threshold,
                                                           int which) {
  // Per thread, as the cache: the caller reads at most two tiles' rows at a time.
  thread_local std::atomic<std::uint32_t> scratch_rows[2][kTileSide];
  std::atomic<std::uint32_t>* scratch = scratch_rows[which];
  const std::uint64_t key = occupancyKey(threshold);
  const FixedThreshold fixed = fixedThreshold(threshold);
  std::uint64_t seen = 0;
  // Only a stale cache is claimed: one filler at a time, and a cache kept for another
  // threshold is left to its user rather than fought over.
  if (t.occ_key.compare_exchange_strong(seen, kFilling, std::memory_order_acquire)) {
    for (int row = 0; row < kTileSide; ++row)
      t.occ_rows[row].store(occupancyRowOf(t.cells, row, fixed, kUnknown),
                            std::memory_order_relaxed);
    t.occ_key.store(key, std::memory_order_release);  // publishes the rows to acquiring readers
    return t.occ_rows;
  }
  if (seen == key) return t.occ_rows;  // filled by another thread meanwhile
  for (int row = 0; row < kTileSide; ++row)
    scratch[row].store(occupancyRowOf(t.cells, row, fixed, kUnknown), std::memory_order_relaxed);
  return scratch;
}

void TiledGrid::exportInt8(const CellBox& box, std::span<std::int8_t> out) const {
  detail::exportInt8(*this, box, out, "TiledGrid");
}

OccupancyMap TiledGrid::toOccupancyMap(const CellBox& box) const {
  return detail::toOccupancyMap(*this, box);
}

std::size_t TiledGrid::tileCount() const {
  return static_cast<std::size_t>(
      std::count_if(table_.begin(), table_.end(), [](const Tile* t) { return t != nullptr; }));
}

std::size_t TiledGrid::uniqueTileCount() const {
  return static_cast<std::size_t>(std::count_if(table_.begin(), table_.end(), [](const Tile* t) {
    return t != nullptr && t->refs.load(std::memory_order_relaxed) == 1;
  }));
}

std::size_t TiledGrid::memoryBytes() const {
  return tileCount() * tileBytes(options_.track_hit_points) + table_.size() * sizeof(Tile*);
}

double TiledGrid::sharedMemoryBytes() const {
  double tiles = 0.0;
  for (const Tile* t : table_)
    if (t != nullptr) tiles += 1.0 / t->refs.load(std::memory_order_relaxed);
  return tiles * static_cast<double>(tileBytes(options_.track_hit_points)) +
         static_cast<double>(table_.size() * sizeof(Tile*));
}

TiledGrid::Counters TiledGrid::counters() {
  return {g_tiles_allocated.load(std::memory_order_relaxed),
          g_tiles_cloned.load(std::memory_order_relaxed)};
}

}  // namespace tessera::grid
