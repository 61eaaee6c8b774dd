#include <tessera/sim/ray_caster.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace tessera::sim {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
}

double RayCaster::cast(const Eigen::Vector2d& origin, double angle, double max_range) const {
  const World& w = *world_;
  const double res = w.resolution();
  const double dx = std::cos(angle), dy = std::sin(angle);

  // A ray starting outside the map begins at the point where it enters the map's rectangle
  // (slab test); one that never enters it hits nothing.
  double t_start = 0;
  if (origin.x() < 0 || origin.y() < 0 || origin.x() >= w.widthMeters() ||
      origin.y() >= w.heightMeters()) {
    double t0 = 0, t1 = kInf;
    auto slab = [&](double o, double d, double hi) {
      if (d == 0) return o >= 0 && o < hi;
      double a = (0 - o) / d, b = (hi - o) / d;
      if (a > b) std::swap(a, b);
      t0 = std::max(t0, a);
      t1 = std::min(t1, b);
      return t0 < t1;
    };
    if (!slab(origin.x(), dx, w.widthMeters()) || !slab(origin.y(), dy, w.heightMeters()))
      return kInf;
    if (t0 > max_range) return kInf;
    t_start = t0;
  }

  const Eigen::Vector2d entry = origin + t_start * Eigen::Vector2d(dx, dy);
  Eigen::Vector2i cell = w.cellOf(entry);
  // The entry point may sit exactly on the far border; keep the cell index inside the map.
  cell.x() = std::clamp(cell.x(), 0, w.width() - 1);
  cell.y() = std::clamp(cell.y(), 0, w.height() - 1);
  if (w.wall(cell.x(), cell.y())) return t_start;

  const int step_x = dx > 0 ? 1 : (dx < 0 ? -1 : 0);
  const int step_y = dy > 0 ? 1 : (dy < 0 ? -1 : 0);
  const double inv_dx = step_x != 0 ? 1.0 / dx : 0.0;
  const double inv_dy = step_y != 0 ? 1.0 / dy : 0.0;

  for (;;) {
    // Distance to the next vertical and horizontal cell boundary, each computed from the
    // origin (not accumulated), so long rays keep full precision.
    const double tx =
        step_x == 0 ? kInf : ((cell.x() + (step_x > 0 ? 1 : 0)) * res - origin.x()) * inv_dx;
    const double ty =
        step_y == 0 ? kInf : ((cell.y() + (step_y > 0 ? 1 : 0)) * res - origin.y()) * inv_dy;
    double t;
    if (tx <= ty) {
      t = tx;
      cell.x() += step_x;
    } else {
      t = ty;
      cell.y() += step_y;
    }
    if (t > max_range || !w.inside(cell.x(), cell.y())) return kInf;
    if (w.wall(cell.x(), cell.y())) return t;
  }
}

// ---- LaserModel ----

double LaserConfig::angleMin() const {
  if (beams == 1) return 0;
  if (fov >= 2 * std::numbers::pi) return -std::numbers::pi;  // a full circle
  return -fov / 2;
}

double LaserConfig::angleIncrement() const {
  if (beams == 1) return fov;  // unused for one beam, but kept positive
  // A full circle: spread beams so the last one does not repeat the first.
  if (fov >= 2 * std::numbers::pi) return fov / beams;
  return fov / (beams - 1);
}

ConfigCheck LaserConfig::check() const {
  ConfigCheck c;
  c.require(fov > 0 && fov <= 2 * std::numbers::pi, "fov", "must be in (0, 2 pi] rad", fov);
  c.require(beams >= 1, "beams", "must be at least 1", beams);
  c.nonNegative("range_min", range_min);
  c.require(range_max > range_min && std::isfinite(range_max), "range_max",
            "must be finite and above range_min", range_max);
  c.nonNegative("range_noise", range_noise).probability("dropout", dropout);
  c.require(allFinite(mount), "mount", "must be finite", mount.theta);
  return c;
}

LaserModel::LaserModel(const World& world, LaserConfig config) : caster_(world), config_(config) {
  config_.validate();
}

void LaserModel::scan(const Pose2& base, std::mt19937_64& rng, std::span<float> ranges) const {
  if (ranges.size() != static_cast<std::size_t>(config_.beams))
    throw std::invalid_argument("laser: output holds " + std::to_string(ranges.size()) +
                                " ranges, the laser has " + std::to_string(config_.beams));
  const Pose2 laser = laserPose(base);
  const double angle_min = config_.angleMin(), angle_increment = config_.angleIncrement();
  std::normal_distribution<double> noise(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  constexpr float kNoReturn = std::numeric_limits<float>::infinity();
  for (int i = 0; i < config_.beams; ++i) {
    const double angle = laser.theta + angle_min + i * angle_increment;
    const double r = caster_.cast(laser.translation(), angle, config_.range_max);
    // Draw for every beam, hit or not, so one beam's outcome does not shift the noise of the
    // others.
    const double z = noise(rng);
    const bool dropped = config_.dropout > 0 && uniform(rng) < config_.dropout;
    if (!std::isfinite(r) || dropped) {
      ranges[i] = kNoReturn;
      continue;
    }
    const double measured = r + config_.range_noise * z;
    if (measured >= config_.range_max)
      ranges[i] = kNoReturn;
    else if (measured < config_.range_min)
      ranges[i] = std::numeric_limits<float>::quiet_NaN();
    else
      ranges[i] = static_cast<float>(measured);
  }
}

std::vector<float> LaserModel::scan(const Pose2& base, std::mt19937_64& rng) const {
  std::vector<float> out(config_.beams);
  scan(base, rng, out);
  return out;
}

}  // namespace tessera::sim
