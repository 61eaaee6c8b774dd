// Commands that run other commands of this executable as child processes: the benchmarks that
// measure whole runs (so that peak RSS and CPU time are that run's alone), the batch's map tasks
// and the overload bench's time-limited runs.
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <string>
#include <vector>

namespace tessera::app {

/// Starts this executable with `args` (args[0] is the program name) in a child process, its stdout
/// and stderr to `log_path` (truncated). Returns the child's pid. Throws std::runtime_error naming
/// `args[1]` when the child cannot be started.
pid_t spawnTessera(const std::vector<std::string>& args, const std::filesystem::path& log_path);

/// The exit code a waitpid() status stands for: the child's exit code, or 128 + the signal that
/// ended it.
int exitCodeOf(int wait_status);

/// Waits for child `pid`. With `limit_s` > 0 it is killed (SIGKILL) once it has run that long and
/// -1 is returned; otherwise returns exitCodeOf its status.
int waitChild(pid_t pid, double limit_s = 0.0);

/// spawnTessera then waitChild.
int runTesseraChild(const std::vector<std::string>& args, const std::filesystem::path& log_path,
                    double limit_s = 0.0);

}  // namespace tessera::app
