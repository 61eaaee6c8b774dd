// Ray casting in a World and the simulated planar laser built on it.
//
// RayCaster::cast walks the grid cell by cell (Amanatides & Woo's exact traversal), so it never
// skips a thin wall and returns the distance to the boundary of the first wall cell the ray
// enters, with no sampling error. Units: metres and radians in the world ("map") frame, angles
// counter-clockwise from +x.
//
// LaserModel turns a base_link pose into one sweep of ranges, following the LaserScan
// conventions of sensor.capnp: beam i points at angle_min + i * angle_increment in the laser
// frame (LaserConfig::angleMin() and angleIncrement(), from its field of view and beam count),
// +inf means no return (nothing within range_max, or a dropout), NaN an invalid reading (closer
// than range_min).
//
// Ownership: both hold a pointer to the World, which must outlive them.
#pragma once

#include <tessera/sim/config_check.hpp>
#include <tessera/sim/robot.hpp>
#include <tessera/sim/world.hpp>

#include <Eigen/Core>

#include <numbers>
#include <random>
#include <span>
#include <vector>

namespace tessera::sim {

class RayCaster {
 public:
  explicit RayCaster(const World& world) : world_(&world) {}

  /// Distance [m] from `origin` along `angle` to the first wall cell, or +inf when no wall lies
  /// within max_range (rays that leave the map hit nothing). 0 when origin is in a wall cell.
  double cast(const Eigen::Vector2d& origin, double angle, double max_range) const;

  const World& world() const { return *world_; }

 private:
  const World* world_;
};

struct LaserConfig {
  /// Field of view [rad], centred on the laser's x axis, in (0, 2 pi]. The beams are evenly
  /// spaced with the first and last on its edges; a full circle starts at -pi and spreads them
  /// so that the last does not repeat the first.
  double fov = 3.141592653589793;
  int beams = 181;
  double range_min = 0.05;    ///< [m] closer returns are invalid (NaN)
  double range_max = 30.0;    ///< [m] nothing at or beyond is seen (+inf)
  double range_noise = 0.01;  ///< std of additive Gaussian range noise [m]
  double dropout = 0.0;       ///< probability that a beam returns nothing (+inf)
  Pose2 mount;                ///< laser pose in base_link

  template <class V>
  void visit(V& v) {
    v("fov", fov, "field of view [rad], centred ahead, in (0, 2 pi]");
    v("beams", beams, "beams per scan, first and last on the edges of the view");
    v("range_min", range_min, "[m] closer readings are invalid (NaN)");
    v("range_max", range_max, "[m] nothing farther is seen (+inf)");
    v("range_noise", range_noise, "std of Gaussian range noise [m]");
    v("dropout", dropout, "probability a beam returns nothing (+inf)");
    PoseFields mount_fields{mount};
    v("mount", mount_fields, "laser pose in base_link");
  }

  /// Angle of the first beam [rad] in the laser frame.
  double angleMin() const;
  /// Angle between beams [rad].
  double angleIncrement() const;
  /// Finds the first bad field (keys as in visit()).
  ConfigCheck check() const;
  /// Throws std::invalid_argument naming the first bad field.
  void validate() const { check().throwIfBad("laser"); }
};

class LaserModel {
 public:
  /// Throws std::invalid_argument for an invalid config.
  LaserModel(const World& world, LaserConfig config);

  /// Fills `ranges` (size config().beams) for base_link at `base` in the world frame, drawing
  /// range noise and dropouts from `rng`.
  void scan(const Pose2& base, std::mt19937_64& rng, std::span<float> ranges) const;
  std::vector<float> scan(const Pose2& base, std::mt19937_64& rng) const;

  /// The laser's pose in the world frame for base_link at `base`.
  Pose2 laserPose(const Pose2& base) const { return compose(base, config_.mount); }
  const LaserConfig& config() const { return config_; }

 private:
  RayCaster caster_;
  LaserConfig config_;
};

}  // namespace tessera::sim
