// Ground-truth relations of the SLAM benchmark of Kümmerle et al., "On measuring the accuracy of
// SLAM algorithms" (Autonomous Robots 27(4), 2009): `*.relations` text files.
//
// One relation per line: `t1 t2 dx dy dz roll pitch yaw`. t1, t2 are time stamps in seconds (the
// time base of the log the relations were made for); (dx, dy, dz) in metres and (roll, pitch,
// yaw) in radians are the true pose of the robot at t2 expressed in its own frame at t1. The 2D
// benchmark files have dz = roll = pitch = 0; they are kept so nothing is lost, the planar metric
// uses (dx, dy, yaw). Blank lines and lines starting with '#' are skipped.
//
// The reader is strict: a line with the wrong number of fields, a non-number or a non-finite value
// throws io::DatasetError naming file:line and field, since a relation silently dropped would bias
// the metric.
#pragma once

#include <tessera/io/text_reader.hpp>

#include <cstdint>
#include <filesystem>
#include <vector>

namespace tessera::datasets {

struct Relation {
  std::int64_t t1_ns = 0;  ///< [ns] time of the reference pose, as in the file (rounded to 1 ns)
  std::int64_t t2_ns = 0;  ///< [ns] time of the pose the relation points to
  double dx = 0, dy = 0, dz = 0;        ///< [m] position at t2 in the frame at t1
  double roll = 0, pitch = 0, yaw = 0;  ///< [rad] orientation at t2 in the frame at t1
};

struct RelationsFile {
  std::vector<Relation> relations;  ///< in file order
  io::ParseReport report;           ///< lines read; nothing is skipped except comments/blanks
};

/// Reads a (possibly gzip) relations file. Throws io::DatasetError.
RelationsFile readRelations(const std::filesystem::path& path);
/// Same, from an open reader (e.g. io::TextReader::fromString in tests).
RelationsFile readRelations(io::TextReader& reader);

}  // namespace tessera::datasets
