// `bench ipc` process control: each process transport's leader and follower are forked children
// held at a gate until their turn, their results written into memory shared with this process,
// and always reaped (killed on error, timeout or Ctrl-C), with the files their iceoryx runtimes
// leave removed, so no process or shared memory outlives the benchmark.
#pragma once

#include "protocol.hpp"

#include <signal.h>
#include <sys/types.h>

#include <array>
#include <chrono>
#include <functional>
#include <string>
#include <vector>

namespace tessera::app::ipc {

/// Catches Ctrl-C / SIGTERM while the bench runs so children are killed and RouDi's shared
/// memory removed by destructors instead of being left behind; restores the old handlers.
class InterruptGuard {
 public:
  InterruptGuard();
  ~InterruptGuard();
  InterruptGuard(const InterruptGuard&) = delete;
  InterruptGuard& operator=(const InterruptGuard&) = delete;
  /// Throws if an interrupt arrived.
  static void check();

 private:
  struct sigaction old_int_ = {};
  struct sigaction old_term_ = {};
};

/// A TransportResult in an anonymous shared mapping (inherited by forked children, no file).
class SharedResult {
 public:
  SharedResult();
  ~SharedResult();
  SharedResult(const SharedResult&) = delete;
  SharedResult& operator=(const SharedResult&) = delete;
  TransportResult& get() { return *result_; }

 private:
  TransportResult* result_;
};

/// Leader and follower of one transport. Destruction kills and reaps whatever still runs.
class Pair {
 public:
  Pair() = default;
  ~Pair();
  Pair(const Pair&) = delete;
  Pair& operator=(const Pair&) = delete;

  /// Forks a child running `body`; it exits 0 on success, 1 with the message in `error` on an
  /// exception, and dies with this process.
  void spawn(const std::function<int()>& body, std::array<char, 256>& error);

  /// Waits for both; on a failure, a timeout or an interrupt the other one is killed. Returns
  /// "" on success, else why it failed.
  std::string wait(std::chrono::seconds timeout);

 private:
  std::vector<pid_t> running_;
};

/// iceoryx leaves the socket /tmp/NAME and the lock /tmp/NAME.lock of a runtime whose process
/// did not deregister (the children _exit, or were killed); removed when this goes, after the
/// children are reaped.
class RuntimeFiles {
 public:
  explicit RuntimeFiles(std::vector<std::string> names) : names_(std::move(names)) {}
  ~RuntimeFiles();
  RuntimeFiles(const RuntimeFiles&) = delete;
  RuntimeFiles& operator=(const RuntimeFiles&) = delete;

 private:
  std::vector<std::string> names_;
};

/// Leader and follower of one transport, forked when this is built and held at a gate until
/// run(). The iceoryx pairs are built before RouDi starts, while this process has one thread:
/// a child forked from a process whose other threads (RouDi's) may hold a lock at that moment
/// can deadlock on it.
class PairRun {
 public:
  /// `runtimes`: the iceoryx runtime names the children register.
  PairRun(std::string name, const std::function<void(TransportResult&)>& leader,
          const std::function<int()>& follower, std::vector<std::string> runtimes = {});
  ~PairRun() { closeGate(); }
  PairRun(const PairRun&) = delete;
  PairRun& operator=(const PairRun&) = delete;

  /// Lets both children start, waits for them and returns the leader's result (valid while
  /// this lives).
  const TransportResult& run(const Options& o);

 private:
  void closeGate();

  std::string name_;
  SharedResult shared_;
  RuntimeFiles files_;  // destroyed after `pair_` reaped the children
  Pair pair_;
  int gate_[2] = {-1, -1};
};

/// Redirects this process's stdout (and its children's) to stderr while it lives.
class StdoutToStderr {
 public:
  StdoutToStderr();
  ~StdoutToStderr();
  StdoutToStderr(const StdoutToStderr&) = delete;
  StdoutToStderr& operator=(const StdoutToStderr&) = delete;

 private:
  int saved_ = -1;
};

}  // namespace tessera::app::ipc
