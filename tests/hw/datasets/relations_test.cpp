#include <tessera/datasets/relations.hpp>

#include <zlib.h>

#include <fstream>

#include "../../shared_data.hpp"

namespace fs = std::filesystem;
using tessera::datasets::readRelations;
using tessera::io::DatasetError;
using tessera::io::TextReader;

namespace {

tessera::datasets::RelationsFile parse(const std::string& text) {
  auto reader = TextReader::fromString("test.relations", text);
  return readRelations(reader);
}

// The message of the DatasetError `text` raises, or "" if it parses.
std::string errorOf(const std::string& text) {
  try {
    parse(text);
  } catch (const DatasetError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("relations reader keeps every field, skips comments and blank lines",
          "[datasets][relations]") {
  const auto file = parse(
      "# t1 t2 dx dy dz roll pitch yaw\n"
      "\n"
      "976052905.167303 976052911.885496 -0.056990 -0.128430 0.0 0.0 0.0 -1.682210\r\n"
      "  10 12.5 1 2 3 0.1 0.2 0.3\n");
  REQUIRE(file.relations.size() == 2);
  CHECK(file.report.lines == 4);
  CHECK(file.report.records == 2);
  const auto& a = file.relations[0];
  // Within a double's resolution at 1e9 s (~0.1 µs).
  CHECK(std::abs(a.t1_ns - 976052905167303000LL) < 200);
  CHECK(std::abs(a.t2_ns - 976052911885496000LL) < 200);
  CHECK(a.dx == -0.056990);
  CHECK(a.dy == -0.128430);
  CHECK(a.yaw == -1.682210);
  const auto& b = file.relations[1];
  CHECK(b.t1_ns == 10'000'000'000LL);
  CHECK(b.t2_ns == 12'500'000'000LL);
  CHECK((b.dz == 3 && b.roll == 0.1 && b.pitch == 0.2 && b.yaw == 0.3));
}

TEST_CASE("relations reader rejects malformed lines naming file, line and field",
          "[datasets][relations]") {
  CHECK_THAT(errorOf("1 2 0 0 0 0 0 0\n1 2 0 0 0 0 0\n"),
             Catch::Contains("test.relations:2:") && Catch::Contains("expected 8 fields"));
  CHECK_THAT(errorOf("1 2 0 0 0 0 0 0 9\n"), Catch::Contains("test.relations:1:"));
  CHECK_THAT(errorOf("# c\n1 2 x 0 0 0 0 0\n"), Catch::Contains("test.relations:2:") &&
                                                    Catch::Contains("(dx)") &&
                                                    Catch::Contains("'x'"));
  CHECK_THAT(errorOf("1 2 0 nan 0 0 0 0\n"), Catch::Contains("(dy)") && Catch::Contains("finite"));
  CHECK_THAT(errorOf("1 2 0 0 0 0 0 inf\n"), Catch::Contains("(yaw)"));
  CHECK_THAT(errorOf("1e300 2 0 0 0 0 0 0\n"),
             Catch::Contains("(t1)") && Catch::Contains("out of range"));
  CHECK_THAT(errorOf("1 -1e11 0 0 0 0 0 0\n"), Catch::Contains("(t2)"));
  // A truncated last line (no newline, fields missing) is an error, not a short file.
  CHECK_THAT(errorOf("1 2 0 0 0 0 0 0\n3 4 0.5"),
             Catch::Contains("test.relations:2:") && Catch::Contains("got 3"));
  CHECK(errorOf("").empty());
  CHECK(parse("").relations.empty());
}

TEST_CASE("relations reader reads gzip files and reports a missing file", "[datasets][relations]") {
  const auto dir = tessera::test::scratchDir("relations");
  const std::string text = "1.5 2.5 0.1 0.2 0 0 0 0.3\n";
  gzFile f = gzopen((dir / "r.relations.gz").c_str(), "wb");
  REQUIRE(f != nullptr);
  gzwrite(f, text.data(), static_cast<unsigned>(text.size()));
  gzclose(f);
  const auto file = readRelations(dir / "r.relations.gz");
  REQUIRE(file.relations.size() == 1);
  CHECK(file.relations[0].t2_ns == 2'500'000'000LL);
  CHECK_THROWS_AS(readRelations(dir / "absent.relations"), DatasetError);
}

TEST_CASE("Intel relations file reads completely", "[datasets][relations][data]") {
  TESSERA_SHARED_DATA(path, "intel-lab-mrpt/intel.relations");
  const auto file = readRelations(path);
  CHECK(file.relations.size() == 2984);
  CHECK(file.report.skipped == 0);
  for (const auto& r : file.relations) {
    // The 2D benchmark: planar relations within the ~45 minutes of the log.
    REQUIRE(r.dz == 0);
    REQUIRE(r.roll == 0);
    REQUIRE(r.pitch == 0);
    REQUIRE(r.t1_ns > 976052800'000'000'000LL);
    REQUIRE(r.t2_ns < 976055600'000'000'000LL);
  }
}
