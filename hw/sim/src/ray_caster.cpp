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

LaserConfig LaserConfig::fromFieldOfView(double fov_deg, int beams) {
  if (!(fov_deg > 0 && fov_deg <= 360)) {
    std::ostringstream s;
    s << "laser: field of view must be in (0, 360] degrees, got " << fov_deg;
    throw std::invalid_argument(s.str());
  }
  if (beams < 1)
    throw std::invalid_argument("laser: beam count must be at least 1, got " +
                                std::to_string(beams));
  LaserConfig c;
  c.beams = beams;
  const double fov = fov_deg * std::numbers::pi / 180;
  if (beams == 1) {
    c.angle_min = 0;
    c.angle_increment = fov;  // unused for one beam, but kept positive
  } else if (fov_deg >= 360) {
    // A full circle: spread beams so the last one does not repeat the first.
    c.angle_min = -std::numbers::pi;
    c.angle_increment = fov / beams;
  } else {
    c.angle_min = -fov / 2;
    c.angle_increment = fov / (beams - 1);
  }
  return c;
}

void LaserConfig::validate() const {
  auto fail = [](const char* what, double v) {
    std::ostringstream s;
    s << "laser: " << what << ", got " << v;
    throw std::invalid_argument(s.str());
  };
  if (beams < 1) fail("beam count must be at least 1", beams);
  if (!(angle_increment > 0) || !std::isfinite(angle_increment))
    fail("angle increment must be positive", angle_increment);
  if (!std::isfinite(angle_min)) fail("angle_min must be finite", angle_min);
  if (!(range_min >= 0) || !std::isfinite(range_min)) fail("minimum range must be >= 0", range_min);
  if (!(range_max > range_min) || !std::isfinite(range_max))
    fail("maximum range must be finite and above the minimum range", range_max);
  if (!(range_noise >= 0) || !std::isfinite(range_noise))
    fail("range noise std must be >= 0", range_noise);
  if (!(dropout >= 0 && dropout <= 1)) fail("dropout probability must be in [0, 1]", dropout);
  if (!std::isfinite(mount.x) || !std::isfinite(mount.y) || !std::isfinite(mount.theta))
    fail("mounting pose must be finite", mount.x);
}

LaserModel::LaserModel(const World& world, LaserConfig config) : caster_(world), config_(config) {
  config_.validate();
}

void LaserModel::scan(const Pose2& base, std::mt19937_64& rng, std::span<float> ranges) const {
  if (ranges.size() != static_cast<std::size_t>(config_.beams))
    throw std::invalid_argument("laser: output holds " + std::to_string(ranges.size()) +
                                " ranges, the laser has " + std::to_string(config_.beams));
  const Pose2 laser = laserPose(base);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  constexpr float kNoReturn = std::numeric_limits<float>::infinity();
  for (int i = 0; i < config_.beams; ++i) {
    const double angle = laser.theta + config_.angle_min + i * config_.angle_increment;
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
