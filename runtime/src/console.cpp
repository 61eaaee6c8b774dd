// Console: signal handling (the first SIGINT/SIGTERM stops the run cleanly, the second exits at
// once; SIGHUP, however often it comes, only stops it cleanly) and the progress line on stderr.
#include "runtime_impl.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <iomanip>
#include <sstream>
#include <string>

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
// SIGHUP: the terminal hung up, or the launcher died (the parent-death signal it sets for its
// workers). The kernel sends the parent-death signal once per thread of the dying launcher, so it
// comes several times; unlike a second Ctrl-C it must not exit without writing outputs.
extern "C" void onHangUp(int) {
  if (auto* rt = g_signal_target.load()) rt->requestStop();
}
}  // namespace

namespace detail {

std::string formatProgress(double fraction, bool finite, double data_s, double wall_s,
                           bool simulated) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1);
  if (finite) {
    fraction = std::clamp(std::isfinite(fraction) ? fraction : 0.0, 0.0, 1.0);
    constexpr int kBar = 20;
    const int full = static_cast<int>(fraction * kBar + 1e-9);
    s << "[progress] [" << std::string(static_cast<std::size_t>(full), '#')
      << std::string(static_cast<std::size_t>(kBar - full), '.') << "] " << std::setw(5)
      << 100.0 * fraction << "% | ";
  } else {
    s << "[running] ";
  }
  s << "data " << data_s << " s | wall " << wall_s << " s";
  if (simulated && wall_s > 0) s << " | " << data_s / wall_s << "x real time";
  if (finite && fraction >= 0.01 && fraction < 1 && wall_s > 0) {
    const double left = wall_s * (1 - fraction) / fraction;
    s << " | ETA ";
    if (left >= 3600)
      s << static_cast<int>(left / 3600) << " h " << static_cast<int>(left / 60) % 60 << " min";
    else if (left >= 60)
      s << static_cast<int>(left / 60) << " min " << static_cast<int>(left) % 60 << " s";
    else
      s << static_cast<int>(std::ceil(left)) << " s";
  }
  return s.str();
}

void printProgress(const Runtime::Impl& rt, bool final_line) {
  double fraction = 0;
  int finite = 0;
  for (const auto& c : rt.actors) {
    if (!c->finite) continue;
    fraction += c->progress.load();
    ++finite;
  }
  const std::string line = formatProgress(finite > 0 ? fraction / finite : 0.0, finite > 0,
                                          nanosToSeconds(rt.clock.now() - rt.start_sim),
                                          nanosToSeconds(steadyNow() - rt.start_wall),
                                          rt.clock.kind() == ClockKind::kSimulated);
  const bool tty = isatty(2);
  std::fprintf(stderr, tty ? "\r%s\033[K%s" : "%s%s", line.c_str(),
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
  sa.sa_handler = onHangUp;
  sigaction(SIGHUP, &sa, nullptr);
}

}  // namespace tessera
