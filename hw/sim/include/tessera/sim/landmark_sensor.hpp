// Range-bearing sensor for point landmarks (docs/algorithms.md#landmark-slam):
//   z = [ sqrt((x_i - x)^2 + (y_i - y)^2),  atan2(y_i - y, x_i - x) - theta ]
// from the sensor pose (base_link pose composed with the mount).
//
// A landmark is seen when its true range lies in [min_range, max_range], its true bearing within
// +-fov/2, and (with occlusion on) no wall cell lies on the ray before it: the ray caster must
// reach within one cell of the landmark, so a landmark drawn on a wall face is still seen.
// Noise: additive Gaussian on range (clamped at 0) and bearing; bearings are wrapped to
// (-pi, pi]. With ids the report carries the landmark id; without, id = -1 and the reports are
// sorted by bearing so their order reveals nothing. Units: metres, radians.
//
// Ownership: the sensor copies the landmarks and, for occlusion, points to a World that must
// outlive it.
#pragma once

#include <tessera/sim/config_check.hpp>
#include <tessera/sim/robot.hpp>
#include <tessera/sim/world.hpp>

#include <random>
#include <vector>

namespace tessera::sim {

struct LandmarkSensorConfig {
  double fov = 3.141592653589793;  ///< full field of view [rad], centred ahead, in (0, 2 pi]
  double max_range = 30;           ///< [m]
  double min_range = 0;            ///< [m]
  double range_noise = 0.1;        ///< std [m]
  double bearing_noise = 0.017453292519943295;  ///< std [rad] (1 deg)
  bool with_ids = true;                         ///< report landmark ids (known data association)
  bool occlusion = false;                       ///< walls of the World hide landmarks
  Pose2 mount;                                  ///< sensor pose in base_link

  template <class V>
  void visit(V& v) {
    v("fov", fov, "field of view [rad], centred ahead, in (0, 2 pi]");
    v("max_range", max_range, "[m] farther landmarks are not seen");
    v("min_range", min_range, "[m] closer landmarks are not seen");
    v("range_noise", range_noise, "range noise std [m]");
    v("bearing_noise", bearing_noise, "bearing noise std [rad] (0.01745 = 1 deg)");
    v("with_ids", with_ids, "report landmark ids (false: id -1, unknown association)");
    v("occlusion", occlusion, "walls of the world hide landmarks");
    PoseFields mount_fields{mount};
    v("mount", mount_fields, "sensor pose in base_link");
  }
  /// Finds the first bad field (keys as in visit()).
  ConfigCheck check() const;
  /// Throws std::invalid_argument naming the first bad field.
  void validate() const { check().throwIfBad("landmark sensor"); }
};

struct RangeBearing {
  int id = -1;       ///< reported id (-1 without ids)
  int true_id = -1;  ///< the landmark it came from (for tests and evaluation only)
  double range = 0, bearing = 0;
};

class LandmarkSensor {
 public:
  /// Throws std::invalid_argument for a bad config, non-finite landmarks, duplicate ids, or
  /// occlusion without a world.
  LandmarkSensor(std::vector<PointLandmark> landmarks, LandmarkSensorConfig config,
                 const World* world = nullptr);

  /// Noise-free measurement of point p from the sensor at `sensor` (world frame).
  static RangeBearing measure(const Pose2& sensor, const Eigen::Vector2d& p);
  /// Whether landmark `lm` is seen from the sensor pose (ignoring noise).
  bool visible(const Pose2& sensor, const PointLandmark& lm) const;
  /// Everything seen from base_link at `base`, with noise drawn from `rng` (two normals per
  /// visible landmark).
  std::vector<RangeBearing> observe(const Pose2& base, std::mt19937_64& rng) const;

  Pose2 sensorPose(const Pose2& base) const { return compose(base, config_.mount); }
  const LandmarkSensorConfig& config() const { return config_; }
  const std::vector<PointLandmark>& landmarks() const { return landmarks_; }

 private:
  std::vector<PointLandmark> landmarks_;
  LandmarkSensorConfig config_;
  const World* world_;
};

}  // namespace tessera::sim
