// Access to the public datasets in ../shared/data for tests. They are not part of the repo: a
// test that needs one calls TESSERA_SHARED_DATA. When the dataset is absent the test fails under
// CI (environment variable CI=true), so CI cannot pass without running it; elsewhere it is
// skipped with a warning naming the missing path, which ctest reports as "Skipped".
#pragma once

#include <catch2/catch.hpp>

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace tessera::test {

inline std::filesystem::path sharedDataDir() {
  return TESSERA_SHARED_DATA_DIR;
}

/// True under CI (CI=true, as CI services set it): a missing dataset is then a failure.
inline bool underCi() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && std::string(ci) == "true";
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

// Declares `const std::filesystem::path var` = ../shared/data/relative; when that is absent,
// fails the test case under CI and skips it elsewhere (the "SKIPPED: dataset" text is what
// tests/CMakeLists.txt tells ctest to report as a skip).
#define TESSERA_SHARED_DATA(var, relative)                                                    \
  const std::filesystem::path var = ::tessera::test::sharedDataDir() / (relative);            \
  if (!std::filesystem::exists(var)) {                                                        \
    if (::tessera::test::underCi()) {                                                         \
      FAIL("dataset " << var.string() << " is absent and CI=true: CI runs every dataset "     \
                      << "test (put the public datasets at ../shared/data beside the repo)"); \
    }                                                                                         \
    WARN("SKIPPED: dataset " << var.string() << " is absent (tests read the public datasets " \
                             << "at ../shared/data beside the repo)");                        \
    return;                                                                                   \
  }
