// Option checks shared by the line cores' constructors (LineExtractor, LineEkfSlam). A failed
// check throws std::invalid_argument whose message starts with the option's key as visit() names
// it, so an actor can put its group's name in front ("ekf.gate_angle must be > 0").
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera::line_slam::detail {

inline void require(bool ok, const char* key, const char* rule) {
  if (!ok) throw std::invalid_argument(std::string(key) + " must be " + rule);
}
inline bool nonNegative(double v) {
  return std::isfinite(v) && v >= 0;
}
inline bool positive(double v) {
  return std::isfinite(v) && v > 0;
}

}  // namespace tessera::line_slam::detail
