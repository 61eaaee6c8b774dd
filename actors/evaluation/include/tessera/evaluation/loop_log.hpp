// The RGB-D loop detector's log (loops.csv, written by rgbd_loop_detector): one row per verified
// loop candidate, accepted or not. Read back by `tessera bench soak` to judge the accepted loops
// against ground truth (checkLoops, loop_metrics.hpp). Columns are found by name in the header, so
// added columns do not break the reader; the ones read are query_id, candidate_id,
// query_stamp_ns, candidate_stamp_ns, accepted (0 or 1) and the candidate-from-query pose
// x, y, z [m], qx, qy, qz, qw (unit quaternion, normalised on reading).
#pragma once

#include <tessera/evaluation/loop_metrics.hpp>
#include <tessera/geometry/pose3.hpp>

#include <cstdint>
#include <filesystem>
#include <vector>

namespace tessera::evaluation {

struct LoggedLoop {
  std::int64_t query_id = 0, candidate_id = 0;
  std::int64_t query_stamp_ns = 0, candidate_stamp_ns = 0;
  bool accepted = false;
  Pose3 candidate_from_query;  ///< the query's camera in the candidate's frame
};

/// Every row of `path`. Throws std::runtime_error naming the file (and line, and column) for a
/// missing or empty file, a header without one of the columns read, a row with another number of
/// fields than the header, a field that is not a number (or not finite), accepted other than 0/1,
/// or a quaternion of length 0.
std::vector<LoggedLoop> readLoopLog(const std::filesystem::path& path);

/// The accepted loops as measurements for checkLoops: from = the candidate's stamp, to = the
/// query's, relative = the query's pose in the candidate's frame.
std::vector<RelativeMeasurement> acceptedLoops(const std::vector<LoggedLoop>& loops);

}  // namespace tessera::evaluation
