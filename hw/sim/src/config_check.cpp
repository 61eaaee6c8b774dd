// ConfigCheck: the first invalid field of a simulator config struct, with its key.
#include <tessera/sim/config_check.hpp>

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace tessera::sim {

ConfigCheck& ConfigCheck::require(bool ok, const char* key, const char* rule, double value) {
  if (!ok && !problem_) {
    std::ostringstream s;
    s << rule << ", got " << value;
    problem_ = ConfigProblem{key, s.str()};
  }
  return *this;
}

ConfigCheck& ConfigCheck::positive(const char* key, double value) {
  return require(value > 0 && std::isfinite(value), key, "must be positive", value);
}

ConfigCheck& ConfigCheck::nonNegative(const char* key, double value) {
  return require(value >= 0 && std::isfinite(value), key, "must be >= 0", value);
}

ConfigCheck& ConfigCheck::probability(const char* key, double value) {
  return require(value >= 0 && value <= 1, key, "is a probability in [0, 1]", value);
}

void ConfigCheck::throwIfBad(const char* what) const {
  if (problem_)
    throw std::invalid_argument(std::string(what) + ": " + problem_->key + " " + problem_->what);
}

bool allFinite(const Pose2& pose) {
  return std::isfinite(pose.x) && std::isfinite(pose.y) && std::isfinite(pose.theta);
}

}  // namespace tessera::sim
