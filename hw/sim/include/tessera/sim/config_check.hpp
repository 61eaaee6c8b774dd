// What the simulator's config structs share: checking their fields, and the sensor mount pose as
// an option group.
//
// ConfigCheck remembers the first invalid field under the key the struct's visit() gives it, so a
// core constructor can throw it (validate()) and an actor can report it under its full dotted
// option key ("laser.range_max") without restating the rules. PoseFields lets a Pose2 field
// appear in a visit() as the group {x [m], y [m], theta [rad]}.
#pragma once

#include <tessera/geometry/pose2.hpp>

#include <optional>
#include <string>

namespace tessera::sim {

/// An invalid field: its key as the struct's visit() names it, and what is wrong with it.
struct ConfigProblem {
  std::string key;
  std::string what;  ///< e.g. "must be >= 0, got -1"
};

class ConfigCheck {
 public:
  /// Records "`rule`, got `value`" for `key` unless `ok`; only the first problem is kept.
  ConfigCheck& require(bool ok, const char* key, const char* rule, double value);
  /// Finite and > 0.
  ConfigCheck& positive(const char* key, double value);
  /// Finite and >= 0.
  ConfigCheck& nonNegative(const char* key, double value);
  /// In [0, 1].
  ConfigCheck& probability(const char* key, double value);

  const std::optional<ConfigProblem>& problem() const { return problem_; }
  /// Throws std::invalid_argument "`what`: KEY RULE, got VALUE" for the first problem.
  void throwIfBad(const char* what) const;

 private:
  std::optional<ConfigProblem> problem_;
};

/// A pose as an option group: `v("mount", PoseFields{mount}, ...)` reads `mount: {x, y, theta}`.
struct PoseFields {
  Pose2& pose;
  template <class V>
  void visit(V& v) {
    v("x", pose.x, "[m]");
    v("y", pose.y, "[m]");
    v("theta", pose.theta, "[rad]");
  }
};

/// Whether every component of the pose is finite.
bool allFinite(const Pose2& pose);

}  // namespace tessera::sim
