// Access to the public datasets in ../shared/data for tests. They are not part of the repo: a
// test that needs one calls TESSERA_SHARED_DATA and is skipped, with a warning naming the
// missing path, when it is absent.
#pragma once

#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <string>

namespace tessera::test {

inline std::filesystem::path sharedDataDir() {
  return TESSERA_SHARED_DATA_DIR;
}

inline std::filesystem::path sourceDir() {
  return TESSERA_SOURCE_DIR;
}

// A fresh empty directory under the system temp dir for one test's outputs.
inline std::filesystem::path scratchDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("tessera_test_" + name + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace tessera::test

// Declares `const std::filesystem::path var` = ../shared/data/relative, or skips the test case.
#define TESSERA_SHARED_DATA(var, relative)                                                    \
  const std::filesystem::path var = ::tessera::test::sharedDataDir() / (relative);            \
  if (!std::filesystem::exists(var)) {                                                        \
    WARN("SKIPPED: dataset " << var.string() << " is absent (tests read the public datasets " \
                             << "at ../shared/data beside the repo)");                        \
    return;                                                                                   \
  }
