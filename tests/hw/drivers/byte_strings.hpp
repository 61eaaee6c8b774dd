// Test helper: a byte string from a list of byte values, for protocol fixtures.
#pragma once

#include <initializer_list>
#include <string>

namespace tessera::test {

inline std::string bytes(std::initializer_list<int> values) {
  std::string s;
  for (const int v : values) s += static_cast<char>(v);
  return s;
}

}  // namespace tessera::test
