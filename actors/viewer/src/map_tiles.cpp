#include <tessera/viewer/map_tiles.hpp>

#include "little_endian.hpp"

#include <cmath>
#include <cstring>
#include <set>
#include <stdexcept>

namespace tessera::viewer {

namespace {

std::int64_t floorDiv(std::int64_t a, std::int64_t b) {
  return a >= 0 ? a / b : -((-a + b - 1) / b);
}

}  // namespace

std::uint64_t tileKey(std::int32_t tx, std::int32_t ty) {
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(ty)) << 32) |
         static_cast<std::uint32_t>(tx);
}

MapTiler::MapTiler(int tile_size) : tile_size_(tile_size) {
  if (tile_size < 1 || tile_size > 1024)
    throw std::invalid_argument("map tiles: tile_size must be in 1..1024, got " +
                                std::to_string(tile_size));
}

MapTiler::Update MapTiler::update(const GridView& g, std::int64_t stamp_ns,
                                  std::int64_t received_wall_ns) {
  if (!(g.resolution > 0) || !std::isfinite(g.resolution))
    throw std::invalid_argument("map tiles: resolution must be > 0 and finite");
  if (g.width < 0 || g.height < 0) throw std::invalid_argument("map tiles: negative grid size");
  const std::int64_t cells = static_cast<std::int64_t>(g.width) * g.height;
  if (cells > 0 && !g.cells) throw std::invalid_argument("map tiles: grid without cells");
  if (static_cast<std::int64_t>(g.cell_count) != cells)
    throw std::invalid_argument("map tiles: a grid of " + std::to_string(g.width) + " x " +
                                std::to_string(g.height) + " cells carries " +
                                std::to_string(g.cell_count) + " cell values");
  if (!std::isfinite(g.origin_x) || !std::isfinite(g.origin_y) || !std::isfinite(g.origin_theta))
    throw std::invalid_argument("map tiles: origin must be finite");
  if (std::abs(g.origin_theta) > 1e-9)
    throw std::invalid_argument("map tiles: rotated grid origins are not drawn (theta " +
                                std::to_string(g.origin_theta) + " rad)");
  const double gx0d = std::round(g.origin_x / g.resolution);
  const double gy0d = std::round(g.origin_y / g.resolution);
  if (std::abs(gx0d) > 1e9 || std::abs(gy0d) > 1e9)
    throw std::invalid_argument("map tiles: origin too far from 0 for the cell lattice");
  const auto gx0 = static_cast<std::int64_t>(gx0d), gy0 = static_cast<std::int64_t>(gy0d);
  const double off_x = g.origin_x - gx0d * g.resolution;
  const double off_y = g.origin_y - gy0d * g.resolution;

  Update u;
  const double tol = 1e-6 * g.resolution;
  if (!have_ || std::abs(g.resolution - resolution_) > 1e-9 * g.resolution ||
      std::abs(off_x - offset_x_) > tol || std::abs(off_y - offset_y_) > tol) {
    u.new_epoch = true;
  }
  const std::int64_t T = tile_size_;
  std::set<std::uint64_t> covered;
  std::vector<std::pair<std::uint64_t, std::string>> current;
  if (g.width > 0 && g.height > 0) {
    const std::int64_t tx0 = floorDiv(gx0, T), tx1 = floorDiv(gx0 + g.width - 1, T);
    const std::int64_t ty0 = floorDiv(gy0, T), ty1 = floorDiv(gy0 + g.height - 1, T);
    for (std::int64_t ty = ty0; ty <= ty1; ++ty)
      for (std::int64_t tx = tx0; tx <= tx1; ++tx) {
        std::string cells(static_cast<std::size_t>(T * T), static_cast<char>(-1));
        for (std::int64_t cy = 0; cy < T; ++cy) {
          const std::int64_t row = ty * T + cy - gy0;  // grid row
          if (row < 0 || row >= g.height) continue;
          const std::int64_t c0 = std::max<std::int64_t>(tx * T, gx0) - gx0;
          const std::int64_t c1 = std::min<std::int64_t>(tx * T + T, gx0 + g.width) - gx0;
          std::memcpy(&cells[static_cast<std::size_t>(cy * T + (c0 + gx0 - tx * T))],
                      g.cells + row * g.width + c0, static_cast<std::size_t>(c1 - c0));
        }
        const std::uint64_t key =
            tileKey(static_cast<std::int32_t>(tx), static_cast<std::int32_t>(ty));
        covered.insert(key);
        current.emplace_back(key, std::move(cells));
      }
  }
  // A tile the grid no longer covers cannot be "unsent": start over.
  if (!u.new_epoch)
    for (const auto& [key, cells] : tiles_)
      if (!covered.count(key)) {
        u.new_epoch = true;
        break;
      }
  if (u.new_epoch) {
    tiles_.clear();
    ++epoch_;
    have_ = true;
    resolution_ = g.resolution;
    offset_x_ = off_x;
    offset_y_ = off_y;
  }
  for (auto& [key, cells] : current) {
    auto it = tiles_.find(key);
    if (it != tiles_.end() && it->second == cells) continue;
    std::string bytes;
    detail::appendLe<std::int32_t>(bytes, static_cast<std::int32_t>(key & 0xffffffffu));
    detail::appendLe<std::int32_t>(bytes, static_cast<std::int32_t>(key >> 32));
    bytes += cells;
    tiles_[key] = std::move(cells);
    u.tiles.emplace_back(key, std::move(bytes));
  }
  u.epoch = epoch_;
  detail::appendLe<double>(u.header, resolution_);
  detail::appendLe<double>(u.header, offset_x_);
  detail::appendLe<double>(u.header, offset_y_);
  detail::appendLe<std::uint32_t>(u.header, static_cast<std::uint32_t>(T));
  detail::appendLe<std::int64_t>(u.header, stamp_ns);
  detail::appendLe<std::int64_t>(u.header, received_wall_ns);
  return u;
}

}  // namespace tessera::viewer
