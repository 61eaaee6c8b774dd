#include <tessera/io/text_reader.hpp>

#include <zlib.h>

#include <fstream>

#include "../../shared_data.hpp"

namespace fs = std::filesystem;
using tessera::io::DatasetError;
using tessera::io::Fields;
using tessera::io::ParseReport;
using tessera::io::TextReader;

namespace {

void writeGzip(const fs::path& path, const std::string& text) {
  gzFile f = gzopen(path.c_str(), "wb");
  REQUIRE(f != nullptr);
  gzwrite(f, text.data(), static_cast<unsigned>(text.size()));
  gzclose(f);
}

std::vector<std::string> allLines(TextReader& reader) {
  std::vector<std::string> lines;
  std::string line;
  while (reader.next(line)) lines.push_back(line);
  return lines;
}

}  // namespace

TEST_CASE("TextReader reads plain and gzip files to the same lines", "[datasets]") {
  const auto dir = tessera::test::scratchDir("text_reader");
  const std::string text = "first line\r\nsecond\n\nlast without newline";
  { std::ofstream(dir / "plain.txt") << text; }
  writeGzip(dir / "packed.log", text);  // the name says nothing: the content does
  TextReader plain(dir / "plain.txt");
  TextReader packed(dir / "packed.log");
  CHECK_FALSE(plain.compressed());
  CHECK(packed.compressed());
  const auto a = allLines(plain);
  const auto b = allLines(packed);
  CHECK(a == std::vector<std::string>{"first line", "second", "", "last without newline"});
  CHECK(a == b);
  CHECK(packed.lineNumber() == 4);
}

TEST_CASE("TextReader reports a truncated gzip file instead of ending quietly", "[datasets]") {
  const auto dir = tessera::test::scratchDir("text_reader_trunc");
  std::string text;
  for (int i = 0; i < 20000; ++i) text += "line " + std::to_string(i) + " with some payload\n";
  writeGzip(dir / "full.gz", text);
  std::ifstream in(dir / "full.gz", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), {});
  std::ofstream(dir / "cut.gz", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  TextReader reader(dir / "cut.gz");
  std::string line;
  CHECK_THROWS_AS(
      [&] {
        while (reader.next(line)) {
        }
      }(),
      DatasetError);
}

TEST_CASE("TextReader names a missing file", "[datasets]") {
  try {
    TextReader reader("/nonexistent/file.log");
    FAIL("expected DatasetError");
  } catch (const DatasetError& e) {
    CHECK(std::string(e.what()).find("/nonexistent/file.log") != std::string::npos);
  }
}

TEST_CASE("Fields converts numbers with checks that name file, line and field", "[datasets]") {
  Fields f("log.txt", 7, "ODOM 1.5 nan 1e999 x12 42 -3", '\0');
  REQUIRE(f.size() == 7);
  CHECK(f.real(1, "x") == 1.5);
  CHECK_THROWS_WITH(f.real(2, "y"), Catch::Contains("log.txt:7: field 3 (y)"));
  CHECK(std::isnan(f.real(2, "y", true)));
  CHECK_THROWS_WITH(f.real(3, "theta"), Catch::Contains("out of range"));
  CHECK_THROWS_WITH(f.integer(4, "count"), Catch::Contains("expected an integer, got 'x12'"));
  CHECK(f.integer(5, "count") == 42);
  CHECK_THROWS_WITH(f.integerIn(5, "count", 0, 10), Catch::Contains("expected 0..10, got 42"));
  CHECK(f.integer(6, "n") == -3);
  CHECK_THROWS_WITH(f.real(9, "v"), Catch::Contains("missing"));
  CHECK_THROWS_WITH(f.requireExactly(3, "ODOM"), Catch::Contains("expected 3 fields, got 7"));
  Fields csv("a.csv", 1, "1,2, 3", ',');
  CHECK(csv.size() == 3);
}

TEST_CASE("ParseReport counts skips by reason and keeps the first examples", "[datasets]") {
  ParseReport report;
  report.lines = 20;
  report.records = 5;
  for (int i = 0; i < 15; ++i) report.skip("f.log", static_cast<std::size_t>(i + 1), "PARAM");
  report.skip("f.log", 16, "garbage");
  CHECK(report.skipped == 16);
  CHECK(report.skipped_by_reason.at("PARAM") == 15);
  CHECK(report.first_skips.size() == ParseReport::max_examples);
  CHECK(report.first_skips.front() == "f.log:1: PARAM");
  CHECK(report.describe().find("PARAM: 15") != std::string::npos);
}

TEST_CASE("TextReader::fromString reads in-memory text like a file", "[datasets]") {
  auto reader = TextReader::fromString("mem.log", "a b\nc\n");
  std::string line;
  REQUIRE(reader.next(line));
  CHECK(line == "a b");
  REQUIRE(reader.next(line));
  CHECK(line == "c");
  CHECK(reader.lineNumber() == 2);
  CHECK_FALSE(reader.next(line));
  CHECK(reader.progress() == 1.0);
  CHECK_THROWS_WITH(reader.fail("bad"), Catch::Contains("mem.log:2: bad"));
}
