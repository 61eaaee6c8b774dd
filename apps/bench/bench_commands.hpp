// The `tessera bench ...` sub-commands, one per benchmark (cmd_bench_*.cpp); addBenchCommands()
// (commands.hpp) registers them under `tessera bench`.
#pragma once

#include <CLI/CLI.hpp>

namespace tessera::app {

/// Adds `tessera bench runtime` (in-process message latency and throughput).
void addBenchRuntimeCommand(CLI::App& bench, int& result);
/// Adds `tessera bench ipc` (two processes: our iceoryx transport vs raw iceoryx, a Unix socket).
void addBenchIpcCommand(CLI::App& bench, int& result);
/// Adds `tessera bench rbpf` (laser SLAM accuracy, CPU and memory on a CARMEN log).
void addBenchRbpfCommand(CLI::App& bench, int& result);
/// Adds `tessera bench camera_network` (seed 000's four-way comparison, with and without cameras).
void addBenchCameraNetworkCommand(CLI::App& bench, int& result);
/// Adds `tessera bench marker_detection` (ArUco detection rate, pixel errors and ms per frame on
/// rendered ceiling-camera images, whole-image search and tracking).
void addBenchMarkerDetectionCommand(CLI::App& bench, int& result);
/// Adds `tessera bench graph` (pose-graph solvers against g2o's figures).
void addBenchGraphCommand(CLI::App& bench, int& result);
/// Adds `tessera bench landmarks` (landmark SLAM accuracy over seeds, cost vs map size).
void addBenchLandmarksCommand(CLI::App& bench, int& result);
/// Adds `tessera bench matcher` (correlative matcher: branch and bound vs exhaustive search).
void addBenchMatcherCommand(CLI::App& bench, int& result);
/// Adds `tessera bench rgbd` (RGB-D visual odometry: our tracker beside OpenCV contrib's).
void addBenchRgbdCommand(CLI::App& bench, int& result);
/// Adds `tessera bench octomap` (OctoMap insertion rate and memory from RGB-D keyframe clouds).
void addBenchOctomapCommand(CLI::App& bench, int& result);
/// Adds `tessera bench planner` (global planners on a synthetic office costmap).
void addBenchPlannerCommand(CLI::App& bench, int& result);
void addBenchNavCommand(CLI::App& bench, int& result);
/// `tessera bench viewer`: the live viewer's CPU cost and map-update latency.
void addBenchViewerCommand(CLI::App& bench, int& result);
/// `tessera bench drivers`: device drivers against their emulated devices.
void addBenchDriversCommand(CLI::App& bench, int& result);
/// `tessera bench dds`: latency over DDS (ours vs raw Cyclone) and robot -> server bandwidth.
void addBenchDdsCommand(CLI::App& bench, int& result);
/// `bench batch`: batch reprocessing against worker processes (cmd_bench_batch.cpp).
void addBenchBatchCommand(CLI::App& bench, int& result);
/// `bench overload`: every profile with sensors at F x real time (cmd_bench_overload.cpp).
void addBenchOverloadCommand(CLI::App& bench, int& result);
/// tessera bench soak: lifelong mapping for H simulated hours (cmd_bench_soak.cpp).
void addBenchSoakCommand(CLI::App& bench, int& result);
/// tessera bench chaos: kills and stalls in a launch deployment (cmd_bench_chaos.cpp).
void addBenchChaosCommand(CLI::App& bench, int& result);

}  // namespace tessera::app
