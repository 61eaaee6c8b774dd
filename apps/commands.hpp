// Sub-commands of the `tessera` CLI. Each registers itself on the CLI11 app and runs when chosen.
#pragma once

#include <tessera/runtime/profile.hpp>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <functional>
#include <string>
#include <utility>
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
/// Adds `tessera map export` (a saved SLAM state to PGM + YAML).
void addMapCommand(CLI::App& app, int& result);
/// Adds `tessera vocab train|info` (bag-of-words vocabularies).
void addVocabCommand(CLI::App& app, int& result);
/// Adds `tessera bench` and its sub-commands; defined apart from the product commands, in the
/// tessera_bench library (apps/bench).
void addBenchCommands(CLI::App& app, int& result);

/// Adds `tessera launch` (a profile as several processes over shared memory) and the internal
/// `tessera worker` it starts for each process.
void addLaunchCommand(CLI::App& app, int& result);

/// `tessera launch PROFILE --host NAME`: process group NAME here, the other groups on other hosts
/// over DDS (cmd_launch_host.cpp).
struct HostLaunchArgs {
  std::string profile, host, out;
  std::vector<std::string> sets;
  int threads = 0;
  int wait_peers_s = 60;
};
int launchHost(const HostLaunchArgs& args);
/// Adds `tessera emulate scip` (an emulated Hokuyo laser on a pty or TCP port).
void addEmulateCommand(CLI::App& app, int& result);
/// Adds `tessera emulate kinect` (a fakenect recording from an RGB-D dataset) under `emulate`.
void addEmulateKinectCommand(CLI::App& emulate, int& result);
/// Adds `tessera doctor` (checks /dev/shm, leftovers, CPU governor, huge pages, datasets).
void addDoctorCommand(CLI::App& app, int& result);
/// Adds `tessera completion bash` (a completion script from the whole command tree: call last).
void addCompletionCommand(CLI::App& app, int& result);
/// Adds `tessera topics` and `tessera echo TOPIC` (a running stack seen through its viewer).
void addTopicsCommands(CLI::App& app, int& result);
/// Adds `tessera goal` (a navigation goal into a launched deployment; --wait follows it).
void addGoalCommand(CLI::App& app, int& result);

/// summary.json of one run (DESIGN.md: outputs).
nlohmann::json summaryJson(const Profile& profile, const RunReport& report);
/// Adds `tessera record` (a profile plus a recorder actor).
void addRecordCommand(CLI::App& app, int& result);
/// Adds `tessera batch` (a recorded RGB-D sequence as parallel map tasks and one reduce).
void addBatchCommand(CLI::App& app, int& result);
/// Adds `tessera replay` (a recording into a profile, or --info).
void addReplayCommand(CLI::App& app, int& result);

/// Settings shared by the commands that run a profile in this process.
struct RunSettings {
  std::vector<std::string> sets;  // --set overrides
  std::string out;                // output folder ("" writes nothing)
  int threads = 0;
  bool quiet = false;
  int view_port = -1;  // --view PORT: add the live viewer (viewer actor); -1: none
  std::string view_address = "127.0.0.1";
  std::string view_token;
};
/// Adds --set, --threads, --quiet and the --view options to a command.
void addRunOptions(CLI::App& cmd, RunSettings& settings);
/// Adds --view, --view-address and --view-token (part of addRunOptions; `launch` adds them alone).
void addViewOptions(CLI::App& cmd, RunSettings& settings);
/// An actor's type and its params, which viewerParams() may change in place.
using ActorParams = std::pair<std::string, YAML::Node>;
/// What --view needs: the viewer actor's params, and the changes to the others' (a localiser
/// listens for initial poses, a map assembler publishes once a second). Shared by `run`, which
/// edits a loaded profile, and `launch`, which edits the profile's YAML for its workers.
YAML::Node viewerParams(const RunSettings& settings, const std::vector<ActorParams>& actors);
/// With --view: adds a viewer actor to `profile` (docs/viewer.md#live) and, unless the pace was
/// given (`rate_given`), runs a simulated clock at real time so there is something to watch.
void applyViewOptions(Profile& profile, const RunSettings& settings, bool rate_given);
/// `base`, or base_2, base_3 ... when the profile already has an actor of that name.
std::string uniqueActorName(const Profile& profile, const std::string& base);
/// An actor added from the command line (its options' errors name the command line).
ActorSpec actorSpec(const std::string& name, const std::string& type, const YAML::Node& params);
/// Runs a loaded profile in this process as `tessera run` does (prints the wiring, progress and
/// metrics, writes summary.json into settings.out) and returns the exit code: 0, 1 when an actor
/// stopped the run with an error, 130 when interrupted. `verb` names the command in messages.
int runProfile(const Profile& profile, const std::string& verb, const RunSettings& settings,
               RunReport* report = nullptr);

}  // namespace tessera::app
