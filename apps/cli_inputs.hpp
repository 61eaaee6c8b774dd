// Input files named on the `tessera` command line: checks that fail with the option's name, the
// folders profile names are looked up in, and loaders shared by the product and bench commands.
#pragma once

#include <tessera/evaluation/trajectory_metrics.hpp>

#include <CLI/CLI.hpp>

#include <string>
#include <vector>

namespace tessera::app {

/// Throws ConfigError "OPTION PATH: no such file" (or "not a regular file").
void requireFile(const std::string& path, const char* option);
/// A check for a number option: finite and within [lo, hi], or above lo when `above` is set
/// (lo excluded). CLI::Range and CLI::PositiveNumber let NaN through (it compares neither below
/// nor above), so every floating-point option of the CLI is checked with this instead.
CLI::Validator finiteNumberIn(double lo, double hi, bool above = false);
/// Folders searched for profile names: the source tree's apps/profiles and ./apps/profiles.
std::vector<std::string> profileSearchDirs();
/// A Kuemmerle et al. relations file as planar relations (checked with requireFile).
std::vector<tessera::evaluation::PoseRelation> loadPoseRelations(const std::string& path,
                                                                 const char* option);

}  // namespace tessera::app
