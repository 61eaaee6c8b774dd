// tessera: run profiles, list actors, benchmark the runtime.
#include "commands.hpp"

#include <tessera/memory/process_allocator.hpp>
#include <tessera/runtime/options.hpp>

#include <iostream>

int main(int argc, char** argv) {
  // Actors free on one thread what another allocated; glibc's defaults keep that memory
  // resident (docs/architecture.md#runtime, "Memory"). The environment's own settings win.
  tessera::memory::tuneProcessAllocator();
  CLI::App app{"Tessera: mapping, localisation and navigation for mobile robots"};
  app.require_subcommand(1);
  int result = 0;
  tessera::app::addRunCommand(app, result);
  tessera::app::addLaunchCommand(app, result);
  tessera::app::addGoalCommand(app, result);
  tessera::app::addTopicsCommands(app, result);
  tessera::app::addActorsCommand(app, result);
  tessera::app::addRecordCommand(app, result);
  tessera::app::addReplayCommand(app, result);
  tessera::app::addBatchCommand(app, result);
  tessera::app::addEvalCommand(app, result);
  tessera::app::addGraphCommand(app, result);
  tessera::app::addMapCommand(app, result);
  tessera::app::addVocabCommand(app, result);
  tessera::app::addEmulateCommand(app, result);
  tessera::app::addDoctorCommand(app, result);
  tessera::app::addBenchCommands(app, result);
  tessera::app::addCompletionCommand(app, result);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help/--version exit 0; every usage error exits 2, as the subcommands' own checks do.
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  } catch (const tessera::ConfigError& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 1;
  }
  return result;
}
