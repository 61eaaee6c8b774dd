#include <tessera/sim/landmark_sensor.hpp>

#include <tessera/sim/ray_caster.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>

namespace tessera::sim {

ConfigCheck LandmarkSensorConfig::check() const {
  ConfigCheck c;
  c.require(fov > 0 && fov <= 2 * std::numbers::pi, "fov", "must be in (0, 2 pi] rad", fov);
  c.nonNegative("min_range", min_range);
  c.require(max_range > min_range && std::isfinite(max_range), "max_range",
            "must be finite and above min_range", max_range);
  c.nonNegative("range_noise", range_noise).nonNegative("bearing_noise", bearing_noise);
  c.require(allFinite(mount), "mount", "must be finite", mount.theta);
  return c;
}

LandmarkSensor::LandmarkSensor(std::vector<PointLandmark> landmarks, LandmarkSensorConfig config,
                               const World* world)
    : landmarks_(std::move(landmarks)), config_(config), world_(world) {
  config_.validate();
  if (config_.occlusion && world_ == nullptr)
    throw std::invalid_argument("landmark sensor: occlusion needs a world");
  std::set<int> ids;
  for (const PointLandmark& lm : landmarks_) {
    if (!lm.position.allFinite())
      throw std::invalid_argument("landmark " + std::to_string(lm.id) + ": position not finite");
    if (lm.id < 0)
      throw std::invalid_argument("landmark ids must be >= 0, got " + std::to_string(lm.id));
    if (!ids.insert(lm.id).second)
      throw std::invalid_argument("duplicate landmark id " + std::to_string(lm.id));
  }
}

RangeBearing LandmarkSensor::measure(const Pose2& sensor, const Eigen::Vector2d& p) {
  const Eigen::Vector2d d = p - sensor.translation();
  RangeBearing z;
  z.range = d.norm();
  z.bearing = normalizeAngle(std::atan2(d.y(), d.x()) - sensor.theta);
  return z;
}

bool LandmarkSensor::visible(const Pose2& sensor, const PointLandmark& lm) const {
  const RangeBearing z = measure(sensor, lm.position);
  if (z.range < config_.min_range || z.range > config_.max_range) return false;
  if (std::abs(z.bearing) > 0.5 * config_.fov) return false;
  if (config_.occlusion && z.range > 0) {
    const double hit =
        RayCaster(*world_).cast(sensor.translation(), sensor.theta + z.bearing, z.range);
    if (hit < z.range - world_->resolution()) return false;
  }
  return true;
}

std::vector<RangeBearing> LandmarkSensor::observe(const Pose2& base, std::mt19937_64& rng) const {
  const Pose2 sensor = sensorPose(base);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<RangeBearing> out;
  for (const PointLandmark& lm : landmarks_) {
    if (!visible(sensor, lm)) continue;
    RangeBearing z = measure(sensor, lm.position);
    const double nr = normal(rng), nb = normal(rng);
    z.range = std::max(0.0, z.range + config_.range_noise * nr);
    z.bearing = normalizeAngle(z.bearing + config_.bearing_noise * nb);
    z.true_id = lm.id;
    z.id = config_.with_ids ? lm.id : -1;
    out.push_back(z);
  }
  if (!config_.with_ids)
    std::sort(out.begin(), out.end(),
              [](const RangeBearing& a, const RangeBearing& b) { return a.bearing < b.bearing; });
  return out;
}

}  // namespace tessera::sim
