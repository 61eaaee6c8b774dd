// `bench ipc` process control (processes.hpp): forked children, the gate that holds them, their
// reaping, and the signal handling that makes an interrupted benchmark clean up.
#include "processes.hpp"

#include <tessera/shm/roudi_host.hpp>

#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <new>
#include <stdexcept>
#include <thread>

namespace tessera::app::ipc {

using namespace std::chrono_literals;

namespace {

volatile std::sig_atomic_t g_interrupted = 0;

extern "C" void onInterrupt(int) {
  g_interrupted = 1;
}

void setError(std::array<char, 256>& error, const std::string& what) {
  std::snprintf(error.data(), error.size(), "%s", what.c_str());
}

}  // namespace

InterruptGuard::InterruptGuard() {
  g_interrupted = 0;
  struct sigaction sa {};
  sa.sa_handler = onInterrupt;
  sigemptyset(&sa.sa_mask);
  ::sigaction(SIGINT, &sa, &old_int_);
  ::sigaction(SIGTERM, &sa, &old_term_);
}

InterruptGuard::~InterruptGuard() {
  ::sigaction(SIGINT, &old_int_, nullptr);
  ::sigaction(SIGTERM, &old_term_, nullptr);
}

void InterruptGuard::check() {
  if (g_interrupted != 0) throw std::runtime_error("bench ipc: interrupted");
}

SharedResult::SharedResult() {
  void* p = ::mmap(nullptr, sizeof(TransportResult), PROT_READ | PROT_WRITE,
                   MAP_SHARED | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) throw std::runtime_error("bench ipc: mmap failed");
  result_ = new (p) TransportResult();
}

SharedResult::~SharedResult() {
  ::munmap(result_, sizeof(TransportResult));
}

Pair::~Pair() {
  for (pid_t pid : running_) {
    ::kill(pid, SIGKILL);
    ::waitpid(pid, nullptr, 0);
  }
}

void Pair::spawn(const std::function<int()>& body, std::array<char, 256>& error) {
  const pid_t parent = ::getpid();
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error("bench ipc: fork failed");
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(1);
    ::signal(SIGINT, SIG_DFL);
    ::signal(SIGTERM, SIG_DFL);
    int code = 1;
    try {
      code = body();
    } catch (const std::exception& e) {
      setError(error, e.what());
    }
    std::fflush(nullptr);
    ::_exit(code);  // no static destructors: they belong to the parent's state
  }
  running_.push_back(pid);
}

std::string Pair::wait(std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::string failure;
  while (!running_.empty()) {
    pid_t pid = 0;
    int status = 0;
    for (pid_t p : running_) {
      if (::waitpid(p, &status, WNOHANG) == p) {
        pid = p;
        break;
      }
    }
    if (pid > 0) {
      running_.erase(std::remove(running_.begin(), running_.end(), pid), running_.end());
      const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
      if (!ok && failure.empty()) {
        failure = WIFSIGNALED(status)
                      ? "a child process died of signal " + std::to_string(WTERMSIG(status))
                      : "a child process failed";
      }
    } else if (failure.empty() && g_interrupted != 0) {
      failure = "interrupted";
    } else if (failure.empty() && std::chrono::steady_clock::now() > deadline) {
      failure = "timed out";
    } else {
      std::this_thread::sleep_for(2ms);
    }
    if (!failure.empty()) {
      for (pid_t p : running_) ::kill(p, SIGKILL);
    }
  }
  return failure;
}

RuntimeFiles::~RuntimeFiles() {
  namespace fs = std::filesystem;
  for (const auto& name : names_) {
    std::error_code ec;
    const fs::path socket = fs::path("/tmp") / name;
    if (fs::is_socket(fs::symlink_status(socket, ec))) fs::remove(socket, ec);
    fs::remove(fs::path("/tmp") / (name + ".lock"), ec);
  }
}

PairRun::PairRun(std::string name, const std::function<void(TransportResult&)>& leader,
                 const std::function<int()>& follower, std::vector<std::string> runtimes)
    : name_(std::move(name)), files_(std::move(runtimes)) {
  if (::pipe(gate_) != 0) throw std::runtime_error("bench ipc: pipe failed");
  auto gated = [this](std::function<int()> body) {
    return [this, body] {
      ::close(gate_[1]);
      char go = 0;
      if (::read(gate_[0], &go, 1) != 1) return 1;  // the bench gave up before starting
      ::close(gate_[0]);
      setIceoryxLogLevel("error");  // as RouDiHost sets it, after these were forked
      return body();
    };
  };
  pair_.spawn(gated(follower), shared_.get().follower_error);
  pair_.spawn(gated([this, leader] {
                leader(shared_.get());
                return 0;
              }),
              shared_.get().leader_error);
  ::close(gate_[0]);
  gate_[0] = -1;
}

const TransportResult& PairRun::run(const Options& o) {
  const char go[2] = {1, 1};
  if (::write(gate_[1], go, sizeof go) != static_cast<ssize_t>(sizeof go)) {
    throw std::runtime_error("bench ipc: " + name_ + ": cannot start the children");
  }
  closeGate();
  // Generous: a sample takes a gap plus at most a few ms even at 4 MiB over the socket.
  const auto timeout =
      std::chrono::seconds(60 + static_cast<long>(o.samples) * static_cast<long>(kSizes.size()) *
                                    (o.gap_us + 10000) / 1000000);
  const std::string failure = pair_.wait(timeout);
  InterruptGuard::check();
  const TransportResult& r = shared_.get();
  if (!failure.empty() || !r.complete) {
    throw std::runtime_error(
        "bench ipc: " + name_ + ": " +
        (r.leader_error[0] != '\0' ? std::string(r.leader_error.data()) : failure) +
        (r.follower_error[0] != '\0' ? "; " + std::string(r.follower_error.data()) : ""));
  }
  return r;
}

void PairRun::closeGate() {
  if (gate_[1] >= 0) ::close(gate_[1]);
  gate_[1] = -1;
}

StdoutToStderr::StdoutToStderr() {
  std::cout.flush();
  std::fflush(stdout);
  saved_ = ::dup(STDOUT_FILENO);
  if (saved_ >= 0) ::dup2(STDERR_FILENO, STDOUT_FILENO);
}

StdoutToStderr::~StdoutToStderr() {
  std::cout.flush();
  std::fflush(stdout);
  if (saved_ >= 0) {
    ::dup2(saved_, STDOUT_FILENO);
    ::close(saved_);
  }
}

}  // namespace tessera::app::ipc
