// LikelihoodField: per-cell log p(endpoint) from the occupancy map's distance transform.
#include <tessera/localization/likelihood_field.hpp>

#include <tessera/config/config_check.hpp>
#include <tessera/grid/distance_transform.hpp>

#include <algorithm>
#include <cmath>
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
  log_p_.resize(distance_.size());
  for (std::size_t i = 0; i < distance_.size(); ++i) {
    float& d = distance_[i];
    d = static_cast<float>(std::min<double>(d * map.resolution, options_.max_distance));
    log_p_[i] = map.cells[i] < 0 ? logP(options_.max_distance) : logP(d);
  }
  log_p_far_ = logP(options_.max_distance);
}

double LikelihoodField::logLikelihood(const Pose2& pose,
                                      std::span<const Eigen::Vector2d> points) const {
  // Robot frame -> the map's cell frame (origin at cell (0,0)'s corner), folded once per call.
  const Pose2 to_grid = between(map_.origin, pose);
  const double gc = std::cos(to_grid.theta), gs = std::sin(to_grid.theta);
  const double inv_res = 1.0 / map_.resolution;
  double sum = 0;
  for (const Eigen::Vector2d& p : points) {
    const double x = to_grid.x + gc * p.x() - gs * p.y();
    const double y = to_grid.y + gs * p.x() + gc * p.y();
    const int col = static_cast<int>(std::floor(x * inv_res));
    const int row = static_cast<int>(std::floor(y * inv_res));
    sum += map_.contains(col, row) ? log_p_[static_cast<std::size_t>(row) * map_.width + col]
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
