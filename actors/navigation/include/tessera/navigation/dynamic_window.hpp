// DynamicWindow: the dynamic window approach to local planning (docs/algorithms.md#local-planning).
//
// Each control period it samples velocity pairs (v [m/s], ω [rad/s]) within the window the
// robot reaches in one period under its acceleration limits (and its speed limits), rolls each
// pair forward as an arc for `horizon` seconds, and measures how far along the arc the
// footprint (a circle) stays clear of obstacles. A pair is admissible when the robot can still
// stop before that point: v ≤ √(2 · clear · brake). Admissible pairs are scored by
//   G = heading_weight · heading + clearance_weight · clearance + velocity_weight · velocity
// with each term divided by its sum over the admissible pairs (so the weights compare like with
// like), heading = π − |bearing of the target from the arc's end pose|, clearance = the clear
// arc length capped at max_clearance, velocity = v. Optionally the score is smoothed over
// neighbouring samples. Poses and the target are in the map frame [m, rad]. On request choose()
// also returns every sampled pair's arc, for display (it costs a rollout of each pair).
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/navigation/costmap.hpp>

#include <Eigen/Core>

#include <vector>

namespace tessera::navigation {

/// A costmap's obstacle distances (obstacleDistance) for lookups by map-frame point.
class DistanceField {
 public:
  DistanceField() = default;
  explicit DistanceField(const Costmap& map);
  /// [m] distance from p's cell centre to the nearest lethal cell centre; 0 outside the map.
  double at(const Eigen::Vector2d& p) const;
  double resolution() const { return geometry_.resolution; }

 private:
  Costmap geometry_;  // the map's geometry; its cells are not kept
  std::vector<float> distance_;
};

struct DynamicWindowOptions {
  double max_speed = 0.5;          ///< [m/s]
  double min_speed = 0.0;          ///< [m/s] (< 0 allows reversing)
  double max_turn_rate = 1.5;      ///< [rad/s]
  double acceleration = 0.5;       ///< [m/s²] linear, both ways
  double turn_acceleration = 2.0;  ///< [rad/s²]
  double brake = 0.5;              ///< [m/s²] deceleration the admissibility test assumes
  double period = 0.05;            ///< [s] control period (20 Hz): the window's reach
  int speed_samples = 11;
  int turn_samples = 21;
  double horizon = 1.5;           ///< [s] arcs are rolled out this long
  double step = 0.05;             ///< [s] rollout step
  double footprint_radius = 0.2;  ///< [m] circular footprint
  double max_clearance = 1.0;     ///< [m] clearance counted up to this
  double heading_weight = 0.8;
  double clearance_weight = 0.2;
  double velocity_weight = 0.2;
  bool smooth = true;  ///< average each score with its 4 grid neighbours

  template <class V>
  void visit(V& v) {
    v("max_speed", max_speed, "[m/s]");
    v("min_speed", min_speed, "[m/s] (< 0 allows reversing)");
    v("max_turn_rate", max_turn_rate, "[rad/s]");
    v("acceleration", acceleration, "[m/s^2] linear acceleration limit");
    v("turn_acceleration", turn_acceleration, "[rad/s^2] angular acceleration limit");
    v("brake", brake, "[m/s^2] braking deceleration for the admissibility test");
    v("period", period, "[s] control period");
    v("speed_samples", speed_samples, "linear velocity samples in the window");
    v("turn_samples", turn_samples, "angular velocity samples in the window");
    v("horizon", horizon, "[s] rollout time of each arc");
    v("step", step, "[s] rollout step");
    v("footprint_radius", footprint_radius, "[m] circular footprint");
    v("max_clearance", max_clearance, "[m] clearance counted up to this");
    v("heading_weight", heading_weight, "weight of the heading term");
    v("clearance_weight", clearance_weight, "weight of the clearance term");
    v("velocity_weight", velocity_weight, "weight of the velocity term");
    v("smooth", smooth, "smooth scores over neighbouring samples");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

struct Velocity {
  double v = 0;  ///< [m/s]
  double w = 0;  ///< [rad/s]
};

/// One sampled pair as the window weighed it (choose() with `with_arcs`).
struct DynamicWindowArc {
  Velocity velocity;
  bool admissible = false;
  double score = 0;      ///< the normalised (and smoothed) score compared; 0 when not admissible
  double clearance = 0;  ///< [m] clear arc length, at most the arc's length over the horizon
  std::vector<Pose2> poses;  ///< map frame: the start pose, then one per `step` to the horizon
};

struct DynamicWindowResult {
  bool ok = false;   ///< an admissible pair was found; otherwise command is (0, 0)
  Velocity command;  ///< for the next period
  int sampled = 0;
  int admissible = 0;
  int chosen = -1;             ///< index of the command among the samples (speed-major); -1: none
  double clearance = 0;        ///< [m] clear arc length of the chosen pair (+inf: no contact)
  std::vector<Pose2> rollout;  ///< the chosen arc, for display
  std::vector<DynamicWindowArc> arcs;  ///< every sample in that order; empty unless asked for
};

class DynamicWindow {
 public:
  explicit DynamicWindow(const DynamicWindowOptions& options = {});

  /// The pair to command now, from the robot's pose and current velocity, a target point to head
  /// for (a look-ahead point on the global path) and the obstacles' distance field. With
  /// `with_arcs` the result also holds every sampled pair's arc (`arcs`, `sampled` of them).
  DynamicWindowResult choose(const Pose2& pose, const Velocity& current,
                             const Eigen::Vector2d& target, const DistanceField& obstacles,
                             bool with_arcs = false) const;

  const DynamicWindowOptions& options() const { return options_; }

 private:
  DynamicWindowOptions options_;
};

}  // namespace tessera::navigation
