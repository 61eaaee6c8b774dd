// Where a module (a .so that tessera loads with dlopen on first use, to keep a heavy dependency
// out of every process: PCL, OpenCV's video and image I/O) can be: it is built beside the
// executables, in bin/, and installed in ../lib next to them.
#pragma once

#include <filesystem>
#include <string_view>
#include <vector>

namespace tessera::io {

/// `file_name` in the running executable's directory and in the directory of the object that
/// holds `anchor` (a symbol of the caller: the executable, or a shared library), each followed by
/// that directory's ../lib; no duplicates, in that order.
std::vector<std::filesystem::path> moduleCandidates(std::string_view file_name, const void* anchor);

}  // namespace tessera::io
