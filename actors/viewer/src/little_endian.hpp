// Little-endian integers and doubles in byte strings: the viewer's wire formats (Foxglove's binary
// frames, map tiles). Private to actors/viewer/src; plain C++17.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

namespace tessera::viewer::detail {

template <class T>
void appendLe(std::string& out, T v) {
  std::uint64_t bits = 0;
  std::memcpy(&bits, &v, sizeof(T));
  for (std::size_t i = 0; i < sizeof(T); ++i)
    out.push_back(static_cast<char>((bits >> (8 * i)) & 0xff));
}

/// Reads a T at `at`; false (v untouched) when `in` is too short.
template <class T>
bool readLe(std::string_view in, std::size_t at, T& v) {
  if (at + sizeof(T) > in.size()) return false;
  std::uint64_t bits = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i)
    bits |= static_cast<std::uint64_t>(static_cast<unsigned char>(in[at + i])) << (8 * i);
  std::memcpy(&v, &bits, sizeof(T));
  return true;
}

}  // namespace tessera::viewer::detail
