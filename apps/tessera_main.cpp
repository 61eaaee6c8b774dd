// tessera: run profiles, list actors, benchmark the runtime.
#include "commands.hpp"

#include <tessera/runtime/options.hpp>

#include <malloc.h>

#include <cstdlib>
#include <iostream>

int main(int argc, char** argv) {
  // glibc gives each thread its own heap arena (up to 8 per core) and every actor and pool
  // thread frees messages and grids that other threads allocated, so each arena keeps its own
  // free pages: 2 arenas hold carmen_global's peak RSS at 60 MB instead of 66-91 MB for the
  // same CPU (docs/architecture.md#runtime). MALLOC_ARENA_MAX in the environment still wins.
  if (std::getenv("MALLOC_ARENA_MAX") == nullptr) mallopt(M_ARENA_MAX, 2);
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
