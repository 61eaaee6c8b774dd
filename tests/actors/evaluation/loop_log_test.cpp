// readLoopLog (rgbd_loop_detector's loops.csv, read back by `tessera bench soak`): a good log
// reads back and its accepted loops become measurements; a missing, empty, truncated, malformed
// or NaN one is an error naming the file, the line and the column.
#include <tessera/evaluation/loop_log.hpp>

#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace loop_log_test {

namespace fs = std::filesystem;
using Catch::Matchers::Contains;
using tessera::evaluation::readLoopLog;

fs::path writeLog(const std::string& name, const std::string& text) {
  const fs::path dir =
      fs::temp_directory_path() / ("tessera_test_loop_log_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path file = dir / name;
  std::ofstream(file, std::ios::binary) << text;
  return file;
}

// As rgbd_loop_detector writes it.
const std::string kHeader =
    "query_id,candidate_id,query_stamp_ns,candidate_stamp_ns,accepted,rejection,matches,inliers,"
    "inlier_ratio,rms_px,depth_agreement,coverage,fit_rms_m,pose_disagreement_m,"
    "pose_disagreement_rad,x,y,z,qx,qy,qz,qw\n";
const std::string kAccepted =
    "120,14,8000000000,900000000,1,none,210,150,0.71,0.8,0.95,0.6,0.01,0.02,0.01,0.1,-0.2,0.3,0,0,"
    "0,2\n";
const std::string kRejected =
    "121,15,8066666667,966666667,0,too_few_inliers,40,8,0.2,2.5,0.5,0.1,0.2,0.5,0.3,0,0,0,0,0,0,1"
    "\r\n";

TEST_CASE("a loop log reads back and gives its accepted loops", "[loop_log]") {
  const auto rows = readLoopLog(writeLog("good.csv", kHeader + kAccepted + kRejected));
  REQUIRE(rows.size() == 2);
  CHECK(rows[0].query_id == 120);
  CHECK(rows[0].candidate_id == 14);
  CHECK(rows[0].query_stamp_ns == 8000000000);
  CHECK(rows[0].candidate_stamp_ns == 900000000);
  CHECK(rows[0].accepted);
  CHECK(rows[0].candidate_from_query.t.isApprox(Eigen::Vector3d(0.1, -0.2, 0.3)));
  CHECK(rows[0].candidate_from_query.q.w() == Approx(1.0));  // normalised
  CHECK_FALSE(rows[1].accepted);
  const auto loops = tessera::evaluation::acceptedLoops(rows);
  REQUIRE(loops.size() == 1);
  CHECK(loops[0].from_ns == 900000000);
  CHECK(loops[0].to_ns == 8000000000);
  // A header alone: no loops. Columns in another order are found by name.
  CHECK(readLoopLog(writeLog("header_only.csv", kHeader)).empty());
  const auto reordered =
      readLoopLog(writeLog("reordered.csv",
                           "accepted,qw,qx,qy,qz,x,y,z,candidate_stamp_ns,query_stamp_ns,"
                           "candidate_id,query_id\n1,1,0,0,0,1,2,3,10,20,4,5\n"));
  REQUIRE(reordered.size() == 1);
  CHECK(reordered[0].query_id == 5);
  CHECK(reordered[0].candidate_from_query.t.z() == 3);
}

TEST_CASE("a bad loop log is an error naming the file, line and column", "[loop_log]") {
  CHECK_THROWS_WITH(readLoopLog("/nonexistent/loops.csv"), Contains("cannot open"));
  CHECK_THROWS_WITH(readLoopLog(writeLog("empty.csv", "")), Contains("empty file"));
  CHECK_THROWS_WITH(readLoopLog(writeLog("other.csv", "t_s,rss_mb\n1,2\n")),
                    Contains("other.csv:1: no column 'query_id'"));
  const std::string cut = kAccepted.substr(0, 40) + "\n";
  CHECK_THROWS_WITH(readLoopLog(writeLog("cut.csv", kHeader + kAccepted + cut)),
                    Contains("cut.csv:3:") && Contains("cut short"));
  // The accepted row with `length` characters at `at` replaced, as the header's only row.
  const auto spoiled = [](std::size_t at, std::size_t length, const std::string& with) {
    std::string row = kAccepted;
    row.replace(at, length, with);
    return kHeader + row;
  };
  const std::size_t x = kAccepted.find("0.1,-0.2");
  CHECK_THROWS_WITH(readLoopLog(writeLog("text.csv", spoiled(x, 3, "abc"))),
                    Contains("text.csv:2: column x") && Contains("'abc'"));
  CHECK_THROWS_WITH(readLoopLog(writeLog("nan.csv", spoiled(x, 3, "nan"))),
                    Contains("nan.csv:2: column x"));
  CHECK_THROWS_WITH(readLoopLog(writeLog("blank.csv", spoiled(0, 3, ""))),
                    Contains("blank.csv:2: column query_id") && Contains("''"));
  CHECK_THROWS_WITH(
      readLoopLog(writeLog("accepted.csv", spoiled(kAccepted.find(",1,none"), 3, ",2,"))),
      Contains("accepted.csv:2: column accepted: expected 0 or 1"));
  // qw 2 -> 0: every component 0.
  CHECK_THROWS_WITH(readLoopLog(writeLog("zero_q.csv", spoiled(kAccepted.size() - 2, 1, "0"))),
                    Contains("zero_q.csv:2: columns qx..qw"));
  fs::remove_all(fs::temp_directory_path() /
                 ("tessera_test_loop_log_" + std::to_string(::getpid())));
}

}  // namespace loop_log_test
