// Where modules are looked for: beside the running executable, then in its ../lib.
#include <tessera/io/module_path.hpp>

#include <catch2/catch.hpp>

#include <filesystem>

namespace module_path_test {

const char kAnchor = 0;

TEST_CASE("a module is looked for beside the executable, then in its ../lib, once each",
          "[io][module_path]") {
  namespace fs = std::filesystem;
  const fs::path exe_dir = fs::weakly_canonical(fs::read_symlink("/proc/self/exe").parent_path());
  // The anchor is in this (statically linked) executable: no second directory.
  const auto files = tessera::io::moduleCandidates("libexample.so", &kAnchor);
  REQUIRE(files.size() == 2);
  CHECK(files[0] == exe_dir / "libexample.so");
  CHECK(files[1] == (exe_dir.parent_path() / "lib" / "libexample.so").lexically_normal());
  CHECK(tessera::io::moduleCandidates("libexample.so", nullptr) == files);
}

}  // namespace module_path_test
