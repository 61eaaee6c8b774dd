// A test helper for writes that fail as on a full disk: run code in a child process whose
// files may not grow past a limit (RLIMIT_FSIZE, SIGXFSZ ignored, so write() fails with EFBIG).
#pragma once

#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <exception>
#include <string>

namespace tessera::test {

/// Runs `body` in a forked child whose files may not grow past `limit` bytes; returns the
/// message of the exception it threw ("" if it threw none). The test process's own limits are
/// unaffected.
template <typename F>
std::string whatWithFileSizeLimit(rlim_t limit, F&& body) {
  int fds[2];
  REQUIRE(::pipe(fds) == 0);
  const pid_t pid = ::fork();
  REQUIRE(pid >= 0);
  if (pid == 0) {
    ::close(fds[0]);
    ::signal(SIGXFSZ, SIG_IGN);
    const rlimit lim{limit, limit};
    if (::setrlimit(RLIMIT_FSIZE, &lim) != 0) ::_exit(3);
    int code = 0;
    std::string what;
    try {
      body();
    } catch (const std::exception& e) {
      what = e.what();
      code = 1;
    }
    if (!what.empty() && ::write(fds[1], what.data(), what.size()) < 0) code = 4;
    ::close(fds[1]);
    ::_exit(code);
  }
  ::close(fds[1]);
  std::string what;
  char buf[512];
  for (ssize_t n; (n = ::read(fds[0], buf, sizeof buf)) > 0;)
    what.append(buf, static_cast<std::size_t>(n));
  ::close(fds[0]);
  int status = 0;
  REQUIRE(::waitpid(pid, &status, 0) == pid);
  REQUIRE(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == (what.empty() ? 0 : 1));
  return what;
}

}  // namespace tessera::test
