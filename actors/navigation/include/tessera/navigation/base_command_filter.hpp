// BaseCommandFilter: velocity commands a differential-drive base can follow. Each step moves the
// output from the last one towards the wanted velocity, clamped to the speed limits, by no more
// than the accelerations allow over the step; a non-finite wanted component counts as 0 (stop),
// so NaN never reaches a motor. Units: metres, radians, seconds. A value type, single-threaded.
#pragma once

namespace tessera::navigation {

struct BaseLimitsOptions {
  double max_speed = 0.5;          ///< [m/s] forward
  double max_reverse = 0.2;        ///< [m/s] backward
  double max_turn_rate = 1.5;      ///< [rad/s]
  double acceleration = 0.8;       ///< [m/s²] linear, speeding up and braking
  double turn_acceleration = 3.0;  ///< [rad/s²]

  template <class V>
  void visit(V& v) {
    v("max_speed", max_speed, "[m/s] top forward speed");
    v("max_reverse", max_reverse, "[m/s] top backward speed");
    v("max_turn_rate", max_turn_rate, "[rad/s] top turn rate");
    v("acceleration", acceleration, "[m/s^2] linear acceleration and braking");
    v("turn_acceleration", turn_acceleration, "[rad/s^2] angular acceleration");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

/// The command sequence a base may follow: each step moves from the last output towards the
/// wanted velocity (clamped to the limits) by at most the accelerations allow over dt.
class BaseCommandFilter {
 public:
  explicit BaseCommandFilter(const BaseLimitsOptions& limits);
  struct Twist {
    double v = 0, w = 0;
  };
  /// The next command after dt seconds towards `wanted` (non-finite components count as 0).
  Twist step(const Twist& wanted, double dt);
  const Twist& last() const { return last_; }

 private:
  BaseLimitsOptions limits_;
  Twist last_;
};

}  // namespace tessera::navigation
