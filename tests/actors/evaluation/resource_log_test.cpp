// readResourceLog (the resource monitor's resources.csv, read back by `tessera bench soak`): a good
// log round-trips; a missing, empty, truncated, malformed or NaN one is an error naming the file,
// the line and the column.
#include <tessera/evaluation/resource_log.hpp>

#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace resource_log_test {

namespace fs = std::filesystem;
using Catch::Matchers::Contains;
using tessera::evaluation::readResourceLog;

fs::path writeLog(const std::string& name, const std::string& text) {
  const fs::path dir =
      fs::temp_directory_path() / ("tessera_test_resource_log_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path file = dir / name;
  std::ofstream(file, std::ios::binary) << text;
  return file;
}

const std::string kHeader = "t_s,rss_mb,cpu_s,scans,submaps,graph_nodes,trimmed\n";

TEST_CASE("a resource log reads back row by row", "[resource_log]") {
  const auto file = writeLog("good.csv", kHeader +
                                             "0,40.5,0.25,0,0,0,0\n"
                                             "3600,48.25,60.5,36000,103,12,91\r\n"
                                             "3600.5,48.3,60.6,36005,103,12,91\n");
  const auto rows = readResourceLog(file);
  REQUIRE(rows.size() == 3);
  CHECK(rows[1].t_s == 3600);
  CHECK(rows[1].rss_mb == 48.25);
  CHECK(rows[1].cpu_s == 60.5);
  CHECK(rows[1].scans == 36000);
  CHECK(rows[1].submaps == 103);
  CHECK(rows[1].graph_nodes == 12);
  CHECK(rows[1].trimmed == 91);
  // The header alone: a run that stopped before its first row.
  CHECK(readResourceLog(writeLog("header_only.csv", kHeader)).empty());
}

TEST_CASE("a bad resource log names the file, the line and what was expected", "[resource_log]") {
  SECTION("missing") {
    CHECK_THROWS_WITH(readResourceLog("/nonexistent/resources.csv"),
                      Contains("/nonexistent/resources.csv: cannot open"));
  }
  SECTION("empty") {
    CHECK_THROWS_WITH(readResourceLog(writeLog("empty.csv", "")),
                      Contains("empty.csv: empty file"));
  }
  SECTION("another header") {
    CHECK_THROWS_WITH(readResourceLog(writeLog("header.csv", "t,rss\n1,2\n")),
                      Contains("header.csv:1: expected the header 't_s,rss_mb"));
  }
  SECTION("a row cut short (a truncated file)") {
    CHECK_THROWS_WITH(readResourceLog(writeLog("cut.csv", kHeader + "0,40,0.2,0,0,0,0\n60,41,1.")),
                      Contains("cut.csv:3: column cpu_s: expected a finite number then ','"));
  }
  SECTION("NaN") {
    CHECK_THROWS_WITH(readResourceLog(writeLog("nan.csv", kHeader + "0,nan,0.2,0,0,0,0\n")),
                      Contains("nan.csv:2: column rss_mb: expected a finite number"));
  }
  SECTION("text and an empty field") {
    CHECK_THROWS_WITH(readResourceLog(writeLog("text.csv", kHeader + "0,40,x,0,0,0,0\n")),
                      Contains("text.csv:2: column cpu_s"));
    CHECK_THROWS_WITH(readResourceLog(writeLog("gap.csv", kHeader + "0,40,1,,0,0,0\n")),
                      Contains("gap.csv:2: column scans"));
  }
  SECTION("an extra column") {
    CHECK_THROWS_WITH(readResourceLog(writeLog("extra.csv", kHeader + "0,40,1,0,0,0,0,9\n")),
                      Contains("extra.csv:2: column trimmed: expected a finite number at the end"));
  }
  SECTION("time that goes back") {
    CHECK_THROWS_WITH(
        readResourceLog(writeLog("back.csv", kHeader + "10,40,1,0,0,0,0\n5,40,1,0,0,0,0\n")),
        Contains("back.csv:3: t_s 5.000000 is earlier than the row before"));
  }
}

}  // namespace resource_log_test
