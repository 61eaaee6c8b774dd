// Tests for tessera/io/atomic_file.hpp: a target holds the previous complete content or the new
// complete content, never part of one; failures name the file and the reason. A full disk is
// played by RLIMIT_FSIZE in a forked child (SIGXFSZ ignored, so write() fails with EFBIG), which
// leaves the limits of the test process alone.
#include <tessera/io/atomic_file.hpp>

#include <catch2/catch.hpp>

#include "../../file_size_limit.hpp"

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>
#include <vector>

namespace atomic_file_test {

namespace fs = std::filesystem;
using namespace tessera::io;
using Catch::Matchers::Contains;

struct Scratch {
  fs::path path;
  Scratch() {
    static int n = 0;
    path = fs::temp_directory_path() /
           ("tessera_atomic_file_" + std::to_string(::getpid()) + "_" + std::to_string(n++));
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~Scratch() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  Scratch(const Scratch&) = delete;
  Scratch& operator=(const Scratch&) = delete;
};

std::string slurp(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void spit(const fs::path& file, const std::string& text) {
  std::ofstream(file, std::ios::binary | std::ios::trunc) << text;
}

std::vector<std::string> names(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.push_back(e.path().filename().string());
  std::sort(out.begin(), out.end());
  return out;
}

using tessera::test::whatWithFileSizeLimit;

TEST_CASE("AtomicFile: commit replaces the old content entirely", "[atomic_file]") {
  Scratch dir;
  const fs::path file = dir.path / "out.txt";
  spit(file, std::string(10000, 'o'));
  {
    AtomicFile f(file);
    f.stream() << "new " << 42 << "\n";
    f.write("done\n");
    // Nothing shows at the target before commit.
    CHECK(slurp(file) == std::string(10000, 'o'));
    CHECK(f.tempPath().parent_path() == file.parent_path());
    CHECK(fs::exists(f.tempPath()));
    f.commit();
  }
  CHECK(slurp(file) == "new 42\ndone\n");
  CHECK(names(dir.path) == std::vector<std::string>{"out.txt"});

  writeFileAtomically(file, "again");
  CHECK(slurp(file) == "again");
  CHECK(names(dir.path) == std::vector<std::string>{"out.txt"});
}

TEST_CASE("AtomicFile: without commit the old file stays and no temporary file remains",
          "[atomic_file]") {
  Scratch dir;
  const fs::path file = dir.path / "map.yaml";
  spit(file, "old complete content\n");
  SECTION("destroyed without commit") {
    AtomicFile f(file);
    f.stream() << std::string(200000, 'x');
    f.flush();
  }
  SECTION("an exception while writing") {
    CHECK_THROWS_WITH(
        [&] {
          AtomicFile f(file);
          f.write("half of it");
          throw std::runtime_error("the writer gave up");
        }(),
        "the writer gave up");
  }
  SECTION("a new file that was never committed does not appear") {
    { AtomicFile f(dir.path / "other.yaml"); }
    CHECK_FALSE(fs::exists(dir.path / "other.yaml"));
  }
  CHECK(slurp(file) == "old complete content\n");
  CHECK(names(dir.path) == std::vector<std::string>{"map.yaml"});
}

TEST_CASE("AtomicFile: temporaries a killed writer left beside the target are removed",
          "[atomic_file]") {
  // A process SIGKILLed while writing (a restarted worker of a launch) cannot remove its
  // temporary file; the next writer of the same target does, unless that process still runs.
  Scratch dir;
  const fs::path file = dir.path / "trajectory.tum";
  const std::string dead = "trajectory.tum.tmp.999999999.3";  // above any pid_max: no such process
  const std::string dead_ext = "trajectory.tmp.999999998.0.tum";
  const std::string alive = "trajectory.tum.tmp." + std::to_string(::getppid()) + ".0";
  const std::string other = "ground_truth.tum.tmp.999999999.0";
  const std::string odd = "trajectory.tum.tmp.notapid.0";
  for (const auto& n : {dead, dead_ext, alive, other, odd}) spit(dir.path / n, "half");
  SECTION("AtomicFile") {
    AtomicFile f(file);
    f.write("complete\n");
    f.commit();
  }
  SECTION("replaceFileAtomically") {
    replaceFileAtomically(file, [](const fs::path& temp) { spit(temp, "complete\n"); });
  }
  CHECK(slurp(file) == "complete\n");
  CHECK(names(dir.path) == std::vector<std::string>{other, "trajectory.tum", alive, odd});
}

TEST_CASE("AtomicFile: a missing folder names the file and the folder", "[atomic_file]") {
  Scratch dir;
  const fs::path file = dir.path / "x" / "map.yaml";
  const std::string folder = (dir.path / "x").string();
  CHECK_THROWS_AS(AtomicFile(file), FileWriteError);
  CHECK_THROWS_WITH(writeFileAtomically(file, "a"),
                    Contains(file.string() + ": cannot create") &&
                        Contains("the folder " + folder + " does not exist"));
  CHECK_THROWS_WITH(replaceFileAtomically(dir.path / "x" / "c.pcd", [](const fs::path&) {}),
                    Contains("c.pcd: cannot create: the folder " + folder + " does not exist"));
  CHECK(names(dir.path).empty());
}

TEST_CASE("AtomicFile: a write that fails (file size limit) names the file and the reason",
          "[atomic_file]") {
  Scratch dir;
  const fs::path file = dir.path / "map.pgm";
  const std::string old(3000, 'o');
  spit(file, old);
  SECTION("one large write") {
    const std::string what =
        whatWithFileSizeLimit(4096, [&] { writeFileAtomically(file, std::string(1 << 20, 'n')); });
    CHECK_THAT(what, Contains(file.string() + ": cannot write: File too large"));
  }
  SECTION("streamed, failing at commit") {
    const std::string what = whatWithFileSizeLimit(4096, [&] {
      AtomicFile f(file);
      for (int i = 0; i < 1000; ++i) f.stream() << "line " << i << " of a long trajectory\n";
      f.commit();
    });
    CHECK_THAT(what, Contains(file.string() + ": cannot write: File too large"));
  }
  SECTION("streamed, failing at flush") {
    const std::string what = whatWithFileSizeLimit(4096, [&] {
      AtomicFile f(file);
      f.stream() << std::string(100000, 'n');
      f.flush();
    });
    CHECK_THAT(what, Contains(file.string() + ": cannot write: File too large"));
  }
  SECTION("a writer that takes a file name") {
    const std::string what = whatWithFileSizeLimit(4096, [&] {
      replaceFileAtomically(file, [](const fs::path& temp) {
        std::ofstream out(temp, std::ios::binary);
        out << std::string(100000, 'n');
        out.close();
        if (!out) throw std::runtime_error(temp.string() + ": write failed");
      });
    });
    CHECK_THAT(what, Contains("write failed"));
  }
  CHECK(slurp(file) == old);
  CHECK(names(dir.path) == std::vector<std::string>{"map.pgm"});
}

TEST_CASE("AtomicFile: under the limit the same child writes fine", "[atomic_file]") {
  Scratch dir;
  const fs::path file = dir.path / "small.txt";
  CHECK(whatWithFileSizeLimit(4096, [&] { writeFileAtomically(file, "fits"); }).empty());
  CHECK(slurp(file) == "fits");
}

TEST_CASE("replaceFileAtomically: the temporary name keeps the extension", "[atomic_file]") {
  Scratch dir;
  const fs::path file = dir.path / "cloud.pcd";
  spit(file, "old");
  fs::path seen;
  replaceFileAtomically(file, [&](const fs::path& temp) {
    seen = temp;
    spit(temp, "new");
  });
  CHECK(seen.parent_path() == dir.path);
  CHECK(seen.extension() == ".pcd");
  CHECK(seen.filename().string().rfind("cloud.tmp.", 0) == 0);
  CHECK(slurp(file) == "new");

  SECTION("a writer that throws leaves the old file") {
    CHECK_THROWS_WITH(replaceFileAtomically(file,
                                            [](const fs::path& temp) {
                                              spit(temp, "half");
                                              throw std::runtime_error("PCL failed");
                                            }),
                      "PCL failed");
  }
  SECTION("a writer that writes nothing is an error") {
    CHECK_THROWS_WITH(replaceFileAtomically(file, [](const fs::path&) {}),
                      Contains(file.string() + ": cannot write: the writer left no file"));
  }
  CHECK(slurp(file) == "new");
  CHECK(names(dir.path) == std::vector<std::string>{"cloud.pcd"});
}

TEST_CASE("AtomicFile: a target that is a folder cannot be replaced", "[atomic_file]") {
  Scratch dir;
  fs::create_directories(dir.path / "taken");
  CHECK_THROWS_WITH(writeFileAtomically(dir.path / "taken", "x"),
                    Contains("taken: cannot replace: "));
  CHECK(names(dir.path) == std::vector<std::string>{"taken"});
}

}  // namespace atomic_file_test
