// Console: SIGINT/SIGTERM handling (first signal stops the run cleanly, the second exits at
// once) and the progress line on stderr.
#include "runtime_impl.hpp"

#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <iomanip>
#include <sstream>

namespace tessera {

namespace {
std::atomic<Runtime*> g_signal_target{nullptr};
std::atomic<int> g_signal_count{0};
extern "C" void onStopSignal(int) {
  if (g_signal_count.fetch_add(1) >= 1) {
    static const char msg[] = "\nsecond interrupt: exiting without writing outputs\n";
    (void)!write(2, msg, sizeof(msg) - 1);
    _exit(130);
  }
  if (auto* rt = g_signal_target.load()) rt->requestStop();
}
}  // namespace

namespace detail {

void printProgress(const Runtime::Impl& rt, bool final_line) {
  double fraction = 0;
  int finite = 0;
  for (const auto& c : rt.actors) {
    if (!c->finite) continue;
    fraction += c->progress.load();
    ++finite;
  }
  const double wall = nanosToSeconds(steadyNow() - rt.start_wall);
  const double sim = nanosToSeconds(rt.clock.now() - rt.start_sim);
  std::ostringstream s;
  s << std::fixed << std::setprecision(1);
  if (finite > 0)
    s << "[progress] " << std::setw(5) << 100.0 * fraction / finite << "% | ";
  else
    s << "[running] ";
  s << "data " << sim << " s | wall " << wall << " s";
  if (rt.clock.kind() == ClockKind::kSimulated && wall > 0)
    s << " | " << sim / wall << "x real time";
  const bool tty = isatty(2);
  std::fprintf(stderr, tty ? "\r%s\033[K%s" : "%s%s", s.str().c_str(),
               (final_line || !tty) ? "\n" : "");
  std::fflush(stderr);
}

void forgetSignalTarget() {
  g_signal_target.store(nullptr);
}

}  // namespace detail

void Runtime::installSignalHandlers() {
  g_signal_target.store(this);
  g_signal_count.store(0);
  struct sigaction sa {};
  sa.sa_handler = onStopSignal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

}  // namespace tessera
