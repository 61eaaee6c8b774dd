// `tessera bench`: registers every benchmark sub-command (bench_commands.hpp) on the CLI.
#include "bench_commands.hpp"

#include "commands.hpp"

namespace tessera::app {

void addBenchCommands(CLI::App& app, int& result) {
  auto* bench = app.add_subcommand("bench", "benchmarks that print their figures and the machine");
  bench->require_subcommand(1);
  addBenchRuntimeCommand(*bench, result);
  addBenchIpcCommand(*bench, result);
  addBenchRbpfCommand(*bench, result);
  addBenchCameraNetworkCommand(*bench, result);
  addBenchMarkerDetectionCommand(*bench, result);
  addBenchGraphCommand(*bench, result);
  addBenchLandmarksCommand(*bench, result);
  addBenchMatcherCommand(*bench, result);
  addBenchRgbdCommand(*bench, result);
  addBenchOctomapCommand(*bench, result);
  addBenchPlannerCommand(*bench, result);
  addBenchNavCommand(*bench, result);
  addBenchViewerCommand(*bench, result);
  addBenchDriversCommand(*bench, result);
  addBenchDdsCommand(*bench, result);
  addBenchBatchCommand(*bench, result);
  addBenchOverloadCommand(*bench, result);
  addBenchSoakCommand(*bench, result);
  addBenchChaosCommand(*bench, result);
}

}  // namespace tessera::app
