// Benchmarks that measure whole runs start each as its own `tessera run` child process, so that
// peak RSS and CPU time are that run's alone.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace tessera::app {

/// Runs this executable with `args` (args[0] is the program name) in a child process, stdout and
/// stderr to `log_path`, and waits for it. Returns its exit code (128 when it did not exit).
/// Throws std::runtime_error when the child cannot be started.
int runTesseraChild(const std::vector<std::string>& args, const std::filesystem::path& log_path);

}  // namespace tessera::app
