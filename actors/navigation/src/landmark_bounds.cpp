// LandmarkBounds: whole-map Dijkstra searches from and to farthest-first landmarks, and the
// cell-by-cell check that a map costs no less than the reference.
#include <tessera/navigation/bucket_queue.hpp>
#include <tessera/navigation/landmark_bounds.hpp>

#include "grid_moves.hpp"

#include <algorithm>
#include <cstddef>
#include <stdexcept>
#include <string>

namespace tessera::navigation {

std::vector<std::uint32_t> costsFrom(const Costmap& map, const StepCosts& steps,
                                     const Eigen::Vector2i& source, bool reverse) {
  constexpr std::uint32_t kNone = LandmarkBounds::kUnreachable;
  std::vector<std::uint32_t> dist(map.cells.size(), kNone);
  if (!map.contains(source) || steps.straight[map.at(source)] == 0) return dist;
  const int w = map.width;
  const std::uint8_t* cells = map.cells.data();
  MonotoneBucketQueue open(steps.max_step);
  const auto s = static_cast<std::int32_t>(map.index(source.x(), source.y()));
  dist[static_cast<std::size_t>(s)] = 0;
  open.push(0, s);
  while (!open.empty()) {
    const auto [key, ui] = open.pop();
    const auto u = static_cast<std::size_t>(ui);
    if (key != dist[u]) continue;  // a cheaper entry of this cell came first
    const int col = ui % w, row = ui / w;
    bool open_side[4] = {false, false, false, false};
    for (int k = 0; k < 8; ++k) {
      const int nc = col + moves::kDx[k], nr = row + moves::kDy[k];
      if (!map.contains(nc, nr)) continue;
      const std::size_t v = map.index(nc, nr);
      const bool passable = steps.straight[cells[v]] != 0;
      if (k < 4) open_side[k] = passable;
      if (!passable || (k >= 4 && !(open_side[moves::kSideX[k]] && open_side[moves::kSideY[k]])))
        continue;
      // Forward the step u → v costs by v's cell; reversed, the step v → u costs by u's.
      const auto& table = k < 4 ? steps.straight : steps.diagonal;
      const std::int64_t g = key + table[cells[reverse ? u : v]];
      if (g >= kNone) throw std::overflow_error("landmark bounds: a path cost exceeds 32 bits");
      if (g < dist[v]) {
        dist[v] = static_cast<std::uint32_t>(g);
        open.push(g, static_cast<std::int32_t>(v));
      }
    }
  }
  return dist;
}

LandmarkBounds::LandmarkBounds(const Costmap& reference, const GridPlannerOptions& options,
                               int count)
    : width_(reference.width), height_(reference.height), steps_(stepCosts(options)) {
  options.validate();
  if (count < 1 || count > 16)
    throw std::invalid_argument("landmark bounds: count must be in [1, 16], got " +
                                std::to_string(count));
  const std::size_t n = reference.cells.size();
  // Seed: the passable cell nearest the map centre; the first landmark is the cell farthest from
  // it, each next one the cell farthest from all landmarks before (by search cost).
  std::size_t seed = n;
  double best = -1;
  for (int row = 0; row < height_; ++row)
    for (int col = 0; col < width_; ++col) {
      if (steps_.straight[reference.at(col, row)] == 0) continue;
      const double dx = col - 0.5 * width_, dy = row - 0.5 * height_;
      const double d2 = dx * dx + dy * dy;
      if (seed == n || d2 < best) seed = reference.index(col, row), best = d2;
    }
  if (seed == n)
    throw std::invalid_argument("landmark bounds: the reference costmap has no passable cell");
  auto cellOf = [&](std::size_t i) {
    return Eigen::Vector2i(static_cast<int>(i % static_cast<std::size_t>(width_)),
                           static_cast<int>(i / static_cast<std::size_t>(width_)));
  };
  std::vector<std::uint32_t> nearest = costsFrom(reference, steps_, cellOf(seed));
  // Written straight into the interleaved table (laid out for `count`; repacked below if the
  // map has fewer distinct cells to offer).
  const auto wanted = static_cast<std::size_t>(count);
  dist_.assign(n * 2 * wanted, kUnreachable);
  for (std::size_t k = 0; k < wanted; ++k) {
    const auto far = static_cast<std::size_t>(
        std::max_element(nearest.begin(), nearest.end(),
                         [](std::uint32_t a, std::uint32_t b) {
                           return (a == kUnreachable ? 0 : a) < (b == kUnreachable ? 0 : b);
                         }) -
        nearest.begin());
    if (k > 0 && (nearest[far] == 0 || nearest[far] == kUnreachable))
      break;  // every reachable cell is a landmark already
    landmarks_.push_back(cellOf(far));
    const std::vector<std::uint32_t> from = costsFrom(reference, steps_, landmarks_.back());
    for (std::size_t i = 0; i < n; ++i) {
      dist_[i * 2 * wanted + k] = from[i];
      nearest[i] = k == 0 ? from[i] : std::min(nearest[i], from[i]);
    }
    const std::vector<std::uint32_t> to = costsFrom(reference, steps_, landmarks_.back(), true);
    for (std::size_t i = 0; i < n; ++i) dist_[i * 2 * wanted + wanted + k] = to[i];
  }
  count_ = static_cast<int>(landmarks_.size());
  if (landmarks_.size() < wanted) {
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < stride(); ++j) {
        const std::size_t k = j % landmarks_.size(), to_part = j / landmarks_.size();
        dist_[i * stride() + j] = dist_[i * 2 * wanted + to_part * wanted + k];
      }
    dist_.resize(n * stride());
  }
  reference_ = reference.cells;
  // Each cell cost as the step model counts it: monotone in the byte up to 252, then never
  // entered (unknown: its unknown_cost when allowed).
  for (int c = 0; c < 256; ++c) {
    const auto b = static_cast<std::uint8_t>(c);
    rank_[static_cast<std::size_t>(c)] =
        steps_.straight[b] == 0
            ? std::uint16_t{0xFFFF}
            : static_cast<std::uint16_t>(b == cost::kUnknown ? options.unknown_cost : b);
  }
}

bool LandmarkBounds::holdsFor(const Costmap& map, const GridPlannerOptions& options) const {
  return holdsFor(map, stepCosts(options));
}

bool LandmarkBounds::holdsFor(const Costmap& map, const StepCosts& steps) const {
  if (map.width != width_ || map.height != height_ || map.cells.size() != reference_.size())
    return false;
  if (steps != steps_) return false;
  const auto& rank = rank_;
  const bool allow_unknown = steps_.straight[cost::kUnknown] != 0;
  const std::uint8_t* q = map.cells.data();
  const std::uint8_t* r = reference_.data();
  const std::size_t n = reference_.size();
  // Without unknown cells allowed the rank never falls as the byte rises, so a block where no
  // byte fell below the reference holds as a whole (a loop the compiler vectorises).
  constexpr std::size_t kBlock = 4096;
  for (std::size_t begin = 0; begin < n; begin += kBlock) {
    const std::size_t end = std::min(n, begin + kBlock);
    if (!allow_unknown) {
      unsigned fell = 0;
      for (std::size_t i = begin; i < end; ++i) fell |= q[i] < r[i] ? 1U : 0U;
      if (fell == 0) continue;
    }
    for (std::size_t i = begin; i < end; ++i)
      if (rank[q[i]] < rank[r[i]]) return false;
  }
  return true;
}

}  // namespace tessera::navigation
