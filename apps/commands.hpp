// Sub-commands of the `tessera` CLI. Each registers itself on the CLI11 app and runs when chosen.
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

namespace tessera::app {

/// Adds `tessera run`; `result` receives the exit code when it runs.
void addRunCommand(CLI::App& app, int& result);
/// Adds `tessera actors` (list registered actor types and their options).
void addActorsCommand(CLI::App& app, int& result);
/// Adds `tessera eval relations|ate|rpe|landmarks` (trajectory and map accuracy).
void addEvalCommand(CLI::App& app, int& result);
/// Adds `tessera graph optimize` (pose-graph files through SGD / Ceres).
void addGraphCommand(CLI::App& app, int& result);
/// Adds `tessera bench graph` (pose-graph solvers against g2o's figures).
void addBenchGraphCommand(CLI::App& bench, int& result);
/// Adds `tessera bench runtime`.
void addBenchRuntimeCommand(CLI::App& bench, int& result);
/// Adds `tessera bench ipc` (two processes: our iceoryx transport vs raw iceoryx, a Unix socket).
void addBenchIpcCommand(CLI::App& bench, int& result);
/// Adds `tessera bench rbpf` (laser SLAM accuracy, CPU and memory on a CARMEN log).
void addBenchRbpfCommand(CLI::App& bench, int& result);
/// Adds `tessera bench landmarks` (landmark SLAM accuracy over seeds, cost vs map size).
void addBenchLandmarksCommand(CLI::App& bench, int& result);
/// Adds `tessera bench matcher` (correlative matcher: branch and bound vs exhaustive search).
void addBenchMatcherCommand(CLI::App& bench, int& result);

/// Folders searched for profile names: the source tree's apps/profiles and ./apps/profiles.
std::vector<std::string> profileSearchDirs();

}  // namespace tessera::app
