// LikelihoodField: per-cell log p(endpoint) from the occupancy map's distance transform.
#include <tessera/localization/likelihood_field.hpp>

#include <tessera/config/config_check.hpp>
#include <tessera/grid/distance_transform.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

namespace tessera::localization {

void LikelihoodFieldOptions::validate() const {
  ConfigCheck()
      .positive("sigma_hit", sigma_hit)
      .nonNegative("z_hit", z_hit)
      .require(std::isfinite(z_rand) && z_rand > 0, "z_rand",
               "must be > 0 (it keeps one bad beam from zeroing a particle)", z_rand)
      .positive("max_distance", max_distance)
      .require(occupied_threshold >= 0 && occupied_threshold <= 100, "occupied_threshold",
               "must be in [0, 100]", occupied_threshold)
      .throwIfBad("likelihood field");
}

LikelihoodField::LikelihoodField(const grid::OccupancyMap& map, double range_max,
                                 const LikelihoodFieldOptions& options)
    : map_(map), options_(options), range_max_(range_max) {
  options_.validate();
  if (map.empty() || map.cells.size() != static_cast<std::size_t>(map.width) * map.height ||
      !(std::isfinite(map.resolution) && map.resolution > 0) || !map.origin.isFinite())
    throw std::invalid_argument(
        "likelihood field: the map is empty, its cells are not width x height, or its "
        "resolution/origin is not finite");
  if (!(std::isfinite(range_max) && range_max > 0))
    throw std::invalid_argument("likelihood field: range_max must be positive, got " +
                                std::to_string(range_max));
  std::vector<std::uint8_t> occupied(map.cells.size());
  for (std::size_t i = 0; i < occupied.size(); ++i)
    occupied[i] = map.cells[i] >= options_.occupied_threshold;
  distance_ = grid::distanceTransform(occupied, map.width, map.height);
  const double norm = 1.0 / (options_.sigma_hit * std::sqrt(2 * std::numbers::pi));
  auto logP = [&](double d) {
    const double z = d / options_.sigma_hit;
    return static_cast<float>(
        std::log(options_.z_hit * norm * std::exp(-0.5 * z * z) + options_.z_rand / range_max));
  };
  // Per cell, a signed distance to the nearest obstacle surface: in a free cell the distance from
  // its centre to the nearest occupied cell's square (centre to centre less half a cell), in an
  // occupied cell minus the distance to the nearest free cell's square. Interpolated between
  // centres its magnitude is 0 on a wall's face, where a beam ends, and grows both in front of
  // and behind it, so a pose that pushes endpoints into walls is penalised as much as one that
  // leaves them short (with 0 inside walls the estimate creeps towards the walls ahead).
  // Unknown cells are NaN: next to one (a SLAM map's wall seen from one side has unknown behind
  // it) the endpoint's own cell decides: unknown is far, occupied is on the surface, free is its
  // distance. See docs/algorithms.md#monte-carlo-localisation.
  std::vector<std::uint8_t> free(map.cells.size());
  for (std::size_t i = 0; i < free.size(); ++i)
    free[i] = map.cells[i] >= 0 && map.cells[i] < options_.occupied_threshold;
  const std::vector<float> to_free = grid::distanceTransform(free, map.width, map.height);
  const double half = 0.5 * map.resolution;
  edge_.resize(distance_.size());
  for (std::size_t i = 0; i < distance_.size(); ++i) {
    float& d = distance_[i];
    d = static_cast<float>(std::min<double>(d * map.resolution, options_.max_distance));
    if (map.cells[i] < 0)
      edge_[i] = std::numeric_limits<float>::quiet_NaN();
    else if (occupied[i])
      edge_[i] = static_cast<float>(
          options_.penalise_inside
              ? -std::min<double>(to_free[i] * map.resolution - half, options_.max_distance)
              : -half);
    else
      edge_[i] = static_cast<float>(std::min<double>(d - half, options_.max_distance));
  }
  // log p by distance, tabulated every kTableStep metres up to max_distance.
  const auto n = static_cast<std::size_t>(std::ceil(options_.max_distance / kTableStep)) + 2;
  table_.resize(n);
  for (std::size_t i = 0; i < n; ++i)
    table_[i] = logP(std::min(static_cast<double>(i) * kTableStep, options_.max_distance));
  log_p_far_ = logP(options_.max_distance);
}

double LikelihoodField::logLikelihood(const Pose2& pose,
                                      std::span<const Eigen::Vector2d> points) const {
  // Robot frame -> the map's cell frame (origin at cell (0,0)'s corner), folded once per call.
  const Pose2 to_grid = between(map_.origin, pose);
  const double gc = std::cos(to_grid.theta), gs = std::sin(to_grid.theta);
  const double inv_res = 1.0 / map_.resolution;
  const double inv_step = 1.0 / kTableStep;
  const int w = map_.width, h = map_.height;
  double sum = 0;
  for (const Eigen::Vector2d& p : points) {
    // In cell units relative to cell centres: (u, v) = (0, 0) at the centre of cell (0, 0).
    const double u = (to_grid.x + gc * p.x() - gs * p.y()) * inv_res - 0.5;
    const double v = (to_grid.y + gs * p.x() + gc * p.y()) * inv_res - 0.5;
    const double fu = std::floor(u), fv = std::floor(v);
    const int c0 = static_cast<int>(fu), r0 = static_cast<int>(fv);
    if (c0 < 0 || r0 < 0 || c0 + 1 >= w || r0 + 1 >= h) {
      sum += log_p_far_;  // off the map, or on its outermost half cell
      continue;
    }
    const double a = u - fu, b = v - fv;
    const float* row0 = edge_.data() + static_cast<std::size_t>(r0) * w + c0;
    const float* row1 = row0 + w;
    double d = (1 - b) * ((1 - a) * row0[0] + a * row0[1]) + b * ((1 - a) * row1[0] + a * row1[1]);
    if (std::isnan(d)) {  // an unknown cell among the four: the endpoint's own cell decides
      const float own = (b < 0.5 ? row0 : row1)[a < 0.5 ? 0 : 1];
      if (std::isnan(own)) {
        sum += log_p_far_;
        continue;
      }
      d = std::max(own, 0.0f);
    }
    const double t = (options_.penalise_inside ? std::abs(d) : std::max(d, 0.0)) * inv_step;
    const auto i = static_cast<std::size_t>(t);
    sum += i + 1 < table_.size()
               ? table_[i] + (t - static_cast<double>(i)) * (table_[i + 1] - table_[i])
               : log_p_far_;
  }
  return sum;
}

double LikelihoodField::distance(const Eigen::Vector2d& p) const {
  const Eigen::Vector2i c = map_.cellOf(p);
  if (!map_.contains(c.x(), c.y())) return options_.max_distance;
  return distance_[static_cast<std::size_t>(c.y()) * map_.width + c.x()];
}

bool LikelihoodField::isFree(const Eigen::Vector2d& p) const {
  const Eigen::Vector2i c = map_.cellOf(p);
  if (!map_.contains(c.x(), c.y())) return false;
  const int v = map_.at(c.x(), c.y());
  return v >= 0 && v < options_.occupied_threshold && distance(p) > 0;
}

}  // namespace tessera::localization
