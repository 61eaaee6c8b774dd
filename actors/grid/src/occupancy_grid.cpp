#include <tessera/grid/occupancy_grid.hpp>

#include "scan_rasterizer.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera::grid {
namespace {

void check(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("OccupancyGrid: " + what);
}

}  // namespace

OccupancyGrid::OccupancyGrid(Options options) : options_(options) {
  detail::checkGridOptions(options_.resolution, options_.log_odds, options_.max_side_cells,
                           "OccupancyGrid");
  check(options_.chunk_cells > 0, "chunk_cells must be > 0");
}

Eigen::Vector2i OccupancyGrid::worldToCell(const Eigen::Vector2d& p) const {
  return detail::cellOf(p, options_.resolution);
}

Eigen::Vector2d OccupancyGrid::cellCenter(const Eigen::Vector2i& c) const {
  return detail::cellCenterOf(c, options_.resolution);
}

Eigen::Vector2d OccupancyGrid::cellCorner(const Eigen::Vector2i& c) const {
  return detail::cellCornerOf(c, options_.resolution);
}

std::size_t OccupancyGrid::indexOf(const Eigen::Vector2i& c) const {
  return static_cast<std::size_t>(c.y() - allocated_.min.y()) *
             static_cast<std::size_t>(allocated_.width()) +
         static_cast<std::size_t>(c.x() - allocated_.min.x());
}

bool OccupancyGrid::isKnown(const Eigen::Vector2i& c) const {
  return allocated_.contains(c) && known_[indexOf(c)] != 0;
}

float OccupancyGrid::logOdds(const Eigen::Vector2i& c) const {
  return isKnown(c) ? log_odds_[indexOf(c)] : 0.0f;
}

double OccupancyGrid::probability(const Eigen::Vector2i& c) const {
  return detail::probabilityOf(logOdds(c));
}

std::int8_t OccupancyGrid::rosValue(float log_odds) {
  const double p = detail::probabilityOf(log_odds);
  return static_cast<std::int8_t>(std::clamp(std::lround(100.0 * p), 0L, 100L));
}

void OccupancyGrid::growToInclude(const CellBox& need, const Eigen::Vector2i& anchor) {
  const CellBox target =
      detail::growBox(allocated_, need, anchor, options_.chunk_cells, options_.max_side_cells);
  if (!allocated_.empty() && target.min == allocated_.min && target.max == allocated_.max) return;

  const std::size_t w = static_cast<std::size_t>(target.width());
  std::vector<float> log_odds(w * static_cast<std::size_t>(target.height()), 0.0f);
  std::vector<std::uint8_t> known(log_odds.size(), 0);
  if (!allocated_.empty()) {
    const int old_w = allocated_.width();
    for (int j = allocated_.min.y(); j <= allocated_.max.y(); ++j) {
      const std::size_t src = indexOf({allocated_.min.x(), j});
      const std::size_t dst = static_cast<std::size_t>(j - target.min.y()) * w +
                              static_cast<std::size_t>(allocated_.min.x() - target.min.x());
      std::copy_n(log_odds_.begin() + src, old_w, log_odds.begin() + dst);
      std::copy_n(known_.begin() + src, old_w, known.begin() + dst);
    }
  }
  allocated_ = target;
  log_odds_ = std::move(log_odds);
  known_ = std::move(known);
}

ScanInsertResult OccupancyGrid::insertScan(const RangeScan& scan, const Pose2& sensor_pose,
                                           const ScanInsertOptions& insert_options) {
  auto& rasterizer = detail::ScanRasterizer::forThisThread();
  ScanInsertResult result =
      rasterizer.classify(scan, sensor_pose, insert_options, options_.resolution);
  if (!rasterizer.hasBeams()) return result;
  growToInclude(rasterizer.need(), rasterizer.originCell());
  rasterizer.collect(allocated_, result);

  const auto& l = options_.log_odds;
  for (const detail::CellUpdate& u : rasterizer.updates()) {
    const std::size_t i = indexOf(u.cell);
    if (known_[i] == 0) {
      known_[i] = 1;
      ++known_count_;
      known_bounds_.extend(u.cell);
    }
    log_odds_[i] = std::clamp(log_odds_[i] + (u.hit ? l.hit : l.miss), l.min, l.max);
  }
  return result;
}

void OccupancyGrid::exportInt8(const CellBox& box, std::span<std::int8_t> out) const {
  detail::exportInt8(*this, box, out, "OccupancyGrid");
}

OccupancyMap OccupancyGrid::toOccupancyMap(const CellBox& box) const {
  return detail::toOccupancyMap(*this, box);
}

}  // namespace tessera::grid
