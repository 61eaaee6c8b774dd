// Helpers the protocol sessions share: seconds to host nanoseconds, and numbers as a person
// reads them in an event ("0.3 s", not "0.300000 s").
#pragma once

#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>

namespace tessera::drivers {

inline std::int64_t nanosOf(double seconds) {
  return static_cast<std::int64_t>(std::llround(seconds * 1e9));
}

inline std::string decimal(double v) {
  std::ostringstream out;
  out << v;
  return out.str();
}

}  // namespace tessera::drivers
