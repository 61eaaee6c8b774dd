// `tessera vocab train|info` end to end: training on the 9 TUM fr1/desk frames (as an RGB-D
// sequence and as a folder of images), describing the result and the shared DBoW3 vocabulary,
// and the usage and bad-file errors.
#include <fstream>

#include "../shared_data.hpp"
#include "cli_run.hpp"

using tessera::test::runCli;

TEST_CASE("vocab train on an RGB-D sequence, then info", "[vocab_cli][dataset]") {
  TESSERA_SHARED_DATA(folder, "tum-rgbd-fr1-desk-9frames");
  const auto dir = tessera::test::scratchDir("vocab_cli");
  const auto out = dir / "desk.tvoc";
  auto run =
      runCli("vocab train --rgbd " + folder.string() + " --k 6 --L 3 --out " + out.string(), dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  CHECK(run.out.find("k 6, L 3") != std::string::npos);
  CHECK(run.err.find("features: 9/9 images") != std::string::npos);  // progress
  REQUIRE(std::filesystem::exists(out));
  run = runCli("vocab info " + out.string(), dir);
  REQUIRE(run.exit_code == 0);
  CHECK(run.out.find("k 6, L 3") != std::string::npos);

  // The same colour images as a plain folder.
  std::filesystem::create_directories(dir / "images");
  for (const auto& e : std::filesystem::directory_iterator(folder / "rgb"))
    std::filesystem::copy_file(e.path(), dir / "images" / e.path().filename());
  run = runCli("vocab train --images " + (dir / "images").string() +
                   " --k 4 --L 2 --every 2 --out " + (dir / "img.tvoc").string(),
               dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  CHECK(run.err.find("features: 5/5 images") != std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST_CASE("vocab info on the shared DBoW3 vocabulary", "[vocab_cli][dataset]") {
  TESSERA_SHARED_DATA(file, "orb-vocabulary-dbow3-small/vocabulary.yml.gz");
  const auto dir = tessera::test::scratchDir("vocab_info");
  const auto run = runCli("vocab info " + file.string(), dir);
  REQUIRE(run.exit_code == 0);
  CHECK(run.out.find("k 10, L 5, 6162 nodes") != std::string::npos);
  CHECK(run.out.find("4983 words") != std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST_CASE("vocab usage errors exit 2, bad files exit 1", "[vocab_cli]") {
  const auto dir = tessera::test::scratchDir("vocab_errors");
  const auto out = (dir / "x.tvoc").string();
  auto run = runCli("vocab train --out " + out, dir);
  CHECK(run.exit_code == 2);
  CHECK(run.err.find("--images or --rgbd") != std::string::npos);
  run = runCli("vocab train --rgbd " + (dir / "none").string() + " --out " + out, dir);
  CHECK(run.exit_code == 2);
  CHECK(run.err.find("no such folder") != std::string::npos);
  run = runCli("vocab train --images " + dir.string() + " --k 1 --out " + out, dir);
  CHECK(run.exit_code == 2);
  CHECK(run.err.find("k must be >= 2") != std::string::npos);
  run = runCli("vocab train --images " + dir.string() + " --out " + out, dir);
  CHECK(run.exit_code == 2);
  CHECK(run.err.find("no .png/.pgm/.jpg images") != std::string::npos);
  run = runCli("vocab info " + (dir / "none.yml").string(), dir);
  CHECK(run.exit_code == 2);
  std::ofstream(dir / "bad.yml") << "%YAML:1.0\nvocabulary:\n   k: 10\n";
  run = runCli("vocab info " + (dir / "bad.yml").string(), dir);
  CHECK(run.exit_code == 1);
  CHECK(run.err.find("bad.yml: vocabulary.L: missing") != std::string::npos);
  std::filesystem::remove_all(dir);
}
