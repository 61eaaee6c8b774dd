// Numbers in refusal messages: fixed notation with a given number of decimals.
#pragma once

#include <sstream>
#include <string>

namespace tessera::camera_network::detail {

inline std::string fixed(double v, int digits) {
  std::ostringstream o;
  o.setf(std::ios::fixed);
  o.precision(digits);
  o << v;
  return o.str();
}

}  // namespace tessera::camera_network::detail
