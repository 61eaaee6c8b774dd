#include "child_process.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <thread>

namespace tessera::app {

pid_t spawnTessera(const std::vector<std::string>& args, const std::filesystem::path& log_path) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0)
    throw std::runtime_error("cannot start a child process for `tessera " +
                             (args.size() > 1 ? args[1] : std::string()) + "`: fork failed");
  if (pid == 0) {
    // Only async-signal-safe calls from here to exec: the parent may have threads.
    if (std::FILE* log = std::fopen(log_path.c_str(), "w")) {
      ::dup2(::fileno(log), 1);
      ::dup2(::fileno(log), 2);
    }
    ::execv("/proc/self/exe", argv.data());
    std::_Exit(127);
  }
  return pid;
}

int exitCodeOf(int status) {
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return 128;
}

int waitChild(pid_t pid, double limit_s) {
  int status = 0;
  if (limit_s <= 0.0) {
    while (::waitpid(pid, &status, 0) < 0)
      if (errno != EINTR) return 128;
    return exitCodeOf(status);
  }
  const auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    const pid_t r = ::waitpid(pid, &status, WNOHANG);
    if (r == pid) return exitCodeOf(status);
    if (r < 0 && errno != EINTR) return 128;
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > limit_s) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}

int runTesseraChild(const std::vector<std::string>& args, const std::filesystem::path& log_path,
                    double limit_s) {
  return waitChild(spawnTessera(args, log_path), limit_s);
}

}  // namespace tessera::app
