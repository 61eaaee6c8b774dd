// Child processes for multi-process tests. A child runs a function and exits with its result;
// the parent always reaps (and on timeout kills) every child, so a failing test leaves no
// process behind. Shared memory is removed by RouDiHost's destructor in the parent.
//
// Fork the children before starting RouDi in the parent: a child forked while RouDi's threads
// run could inherit a lock one of them held. Children wait at a gate until open() (call it once
// RouDi is up), so they never touch iceoryx before it exists.
#pragma once

#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <functional>
#include <string>
#include <thread>
#include <vector>

namespace tessera::test {

class Children {
 public:
  ~Children() {
    if (gate_[1] >= 0) {  // never opened: the children exit with 102
      ::close(gate_[1]);
      ::close(gate_[0]);
    }
    for (auto& c : children_) {
      if (c.pid > 0 && !c.reaped) {
        ::kill(c.pid, SIGKILL);
        int status = 0;
        ::waitpid(c.pid, &status, 0);
      }
    }
  }

  /// Forks a child that waits for open(), runs `body` and exits with its return value
  /// (exceptions: 101; gate closed without opening: 102).
  pid_t spawn(std::function<int()> body) {
    if (gate_[0] < 0 && ::pipe(gate_) != 0) return -1;
    const pid_t pid = ::fork();
    if (pid == 0) {
      ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // never outlive the test process
      ::close(gate_[1]);
      char go = 0;
      if (::read(gate_[0], &go, 1) != 1) ::_exit(102);
      int code = 100;
      try {
        code = body();
      } catch (const std::exception& e) {
        std::fprintf(stderr, "child failed: %s\n", e.what());
        code = 101;
      }
      std::fflush(nullptr);
      ::_exit(code);
    }
    children_.push_back({pid, false});
    return pid;
  }

  /// Lets every spawned child run.
  void open() {
    if (gate_[1] < 0) return;
    const char go[64] = {};
    (void)!::write(gate_[1], go, children_.size());
    ::close(gate_[1]);
    ::close(gate_[0]);
    gate_[0] = gate_[1] = -1;
  }

  /// Waits for `pid`; returns its exit code, 128+signal when killed, -1 on timeout (then it is
  /// killed).
  int wait(pid_t pid, std::chrono::seconds timeout = std::chrono::seconds(60)) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (auto& c : children_) {
      if (c.pid != pid) continue;
      int status = 0;
      while (true) {
        const pid_t r = ::waitpid(pid, &status, WNOHANG);
        if (r == pid) break;
        if (std::chrono::steady_clock::now() > deadline) {
          ::kill(pid, SIGKILL);
          ::waitpid(pid, &status, 0);
          c.reaped = true;
          return -1;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
      c.reaped = true;
      if (WIFEXITED(status)) return WEXITSTATUS(status);
      return 128 + WTERMSIG(status);
    }
    return -2;
  }

 private:
  struct Child {
    pid_t pid;
    bool reaped;
  };
  std::vector<Child> children_;
  int gate_[2] = {-1, -1};
};

}  // namespace tessera::test
