// ConfigCheck: checking the fields of a core's options struct in one place.
//
// It remembers the first invalid field under the key the struct's visit() gives it, so a core
// constructor can throw it (throwIfBad) and an actor can report it under its full dotted option
// key ("laser.range_max") without restating the rules. Cores of every domain use it; the runtime
// turns the exception into a ConfigError naming the actor.
#pragma once

#include <optional>
#include <string>

namespace tessera {

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
  /// Throws std::invalid_argument "KEY RULE, got VALUE" for the first problem, prefixed
  /// "`what`: " unless `what` is empty.
  void throwIfBad(const char* what = "") const;

 private:
  std::optional<ConfigProblem> problem_;
};

}  // namespace tessera
