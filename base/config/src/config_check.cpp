// ConfigCheck: the first invalid field of an options struct, with its key.
#include <tessera/config/config_check.hpp>

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace tessera {

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
  if (!problem_) return;
  const std::string prefix = (what && *what) ? std::string(what) + ": " : std::string();
  throw std::invalid_argument(prefix + problem_->key + " " + problem_->what);
}

}  // namespace tessera
