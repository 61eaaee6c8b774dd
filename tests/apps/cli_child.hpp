// A `tessera` command running in the background for tests that talk to it while it runs (the
// live viewer): started with fork/exec, stderr in a file, stopped with SIGINT as Ctrl-C would.
#pragma once

#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <thread>

namespace tessera::test {

// A child `tessera ARGS` with stderr in a file; stopped with SIGINT (as Ctrl-C) on request.
class CliChild {
 public:
  CliChild(const std::string& args, const std::filesystem::path& err) {
    pid_ = ::fork();
    REQUIRE(pid_ >= 0);
    if (pid_ == 0) {
      const std::string cmd = "exec " + std::string(TESSERA_CLI_PATH) + " " + args + " 2> " +
                              err.string() + " > /dev/null";
      ::execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
  }
  ~CliChild() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  int interrupt() {
    ::kill(pid_, SIGINT);
    int status = 0;
    for (int i = 0; i < 600; ++i) {
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return -2;
  }

 private:
  pid_t pid_ = -1;
};

/// The viewer's page URL a run prints ("live view: http://127.0.0.1:PORT/"), waiting up to 60 s;
/// "" when it never comes.
inline std::string waitForViewerUrl(const std::filesystem::path& stderr_file) {
  const std::regex url_re(R"(live view: (http://127\.0\.0\.1:[0-9]+/))");
  for (int i = 0; i < 600; ++i) {
    std::ifstream in(stderr_file);
    std::ostringstream s;
    s << in.rdbuf();
    const std::string text = s.str();
    std::smatch m;
    if (std::regex_search(text, m, url_re)) return m[1];
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return "";
}

}  // namespace tessera::test
