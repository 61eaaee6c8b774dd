// Input files named on the `tessera` command line: checks that fail with the option's name, and
// loaders shared by the eval and bench commands.
#pragma once

#include <tessera/evaluation/trajectory_metrics.hpp>

#include <string>
#include <vector>

namespace tessera::app {

/// Throws ConfigError "OPTION PATH: no such file" (or "not a regular file").
void requireFile(const std::string& path, const char* option);
/// A Kuemmerle et al. relations file as planar relations (checked with requireFile).
std::vector<tessera::evaluation::PoseRelation> loadPoseRelations(const std::string& path,
                                                                 const char* option);

}  // namespace tessera::app
