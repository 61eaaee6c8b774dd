// Timers and the run loop: the runtime's lifecycle (start, run, stop), timers firing on the
// simulated or wall clock, manual stepping, and the end of a run (stop reason, actors stopped
// upstream first, final report). Times are ns of the runtime's clock.
#include "runtime_impl.hpp"

#include <tessera/runtime/process_stats.hpp>

#include <unistd.h>

#include <algorithm>
#include <stdexcept>
#include <thread>

namespace tessera {

Runtime::Impl::Impl(RuntimeOptions o)
    : options(std::move(o)), clock(options.clock, options.sim_start, options.sim_rate) {}

Runtime::Runtime(RuntimeOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}

Runtime::~Runtime() {
  if (impl_->arena || impl_->pool) {
    impl_->stop_requested = true;
    impl_->waitIdle();
  }
}

const Clock& Runtime::clock() const {
  return impl_->clock;
}

// ---------------------------------------------------------------- timers

Nanos Runtime::Impl::nextTimerDue() {
  Nanos due = detail::Timer::kIdle;
  std::lock_guard lock(timers_mutex);
  for (const auto& t : timers) due = std::min(due, t.next);
  return due;
}

void Runtime::Impl::fireTimersDueBy(Nanos now) {
  std::vector<std::size_t> fire;
  {
    std::lock_guard lock(timers_mutex);
    for (std::size_t i = 0; i < timers.size(); ++i) {
      auto& t = timers[i];
      if (t.next > now) continue;
      fire.push_back(i);
      if (t.period == 0) {
        t.next = detail::Timer::kIdle;
        continue;
      }
      t.next += t.period;
      if (t.next <= now) {  // fell behind by more than a period: skip, don't burst
        ++t.overruns;
        t.next = now + t.period;
      }
    }
  }
  for (auto i : fire) queueTimer(i);
}

bool Runtime::Impl::fireDueTimers(Nanos limit) {
  const bool sim = clock.kind() == ClockKind::kSimulated;
  const Nanos due = nextTimerDue();
  if (due > limit) {
    if (sim) clock.advanceTo(limit);
    return false;
  }
  if (sim) clock.advanceTo(due);
  fireTimersDueBy(due);
  return true;
}

void Runtime::Impl::queueTimer(std::size_t index) {
  std::uint32_t actor;
  {
    std::lock_guard lock(timers_mutex);
    auto& t = timers[index];
    if (t.queued) {
      ++t.overruns;
      return;
    }
    t.queued = true;
    actor = t.actor;
  }
  enqueue(*actors[actor], detail::Item{-static_cast<std::int32_t>(index) - 1, 0, nullptr});
}

bool Runtime::fireDueTimers(Nanos limit) {
  return impl_->fireDueTimers(limit);
}

// ---------------------------------------------------------------- start, manual stepping

void Runtime::start() {
  if (!impl_->configured) configure();
  if (impl_->started) return;
  impl_->start_sim = impl_->clock.now();
  impl_->start_wall = steadyNow();
  impl_->start_cpu = processCpuSeconds();
  if (!impl_->options.manual) impl_->startExecutor();
  for (auto& c : impl_->actors) c->instance->start();
  impl_->started = true;
  if (!impl_->options.manual) {
    // Messages queued before start. Only actors that have some: a drain of an empty inbox would
    // hold the strand for a moment, and a message imported then could not run at once.
    for (auto& c : impl_->actors) {
      bool queued = false;
      {
        std::lock_guard lock(c->mutex);
        queued = !c->queue.empty();
      }
      if (queued) impl_->schedule(*c);
    }
  }
}

bool Runtime::step() {
  return impl_->stepOne();
}

std::size_t Runtime::runUntilIdle() {
  std::size_t n = 0;
  while (impl_->stepOne()) ++n;
  return n;
}

// ---------------------------------------------------------------- stopping

void Runtime::requestStop() {
  // Async-signal-safe: only an atomic store (the reason is filled in by run()).
  impl_->stop_requested.store(true);
}

void Runtime::Impl::requestStop(const std::string& reason) {
  {
    std::lock_guard lock(stop_reason_mutex);
    if (stop_reason.empty()) stop_reason = reason;
  }
  stop_requested.store(true);
}

void Runtime::Impl::settle() {
  if (options.manual) {
    while (stepOne()) {
    }
  } else {
    waitIdle();
  }
}

void Runtime::Impl::stopActors(const std::vector<std::uint32_t>& order) {
  for (auto i : order) {
    settle();
    try {
      actors[i]->instance->stop();
    } catch (const std::exception& e) {
      // One actor failing to flush must not stop the others from writing their outputs.
      std::fprintf(stderr, "error: actor '%s' failed in stop(): %s\n", actors[i]->name.c_str(),
                   e.what());
      std::lock_guard lock(stop_reason_mutex);
      stop_reason += (stop_reason.empty() ? "" : "; ") +
                     ("actor '" + actors[i]->name + "' failed in stop(): " + e.what());
    }
  }
  settle();
}

void Runtime::Impl::stopActorsInTurns(RunCoordinator& coordinator) {
  // The deployment interleaves the processes' actors in one stop order: a process may stop
  // some actors, then others of another process, then more of its own.
  for (;;) {
    const auto names = coordinator.awaitStopTurn([&] { return pending.load() != 0; });
    if (names.empty()) break;
    std::vector<std::uint32_t> order;
    for (const auto& name : names) {
      for (std::uint32_t i = 0; i < actors.size(); ++i) {
        if (actors[i]->name == name) order.push_back(i);
      }
    }
    stopActors(order);
    coordinator.stopped();
  }
}

void Runtime::Impl::finish() {
  closed.store(true);
  final_report = makeReport();
  stopExecutor();
}

void Runtime::stop() {
  if (!impl_->started || impl_->stopped) return;
  impl_->stopped = true;
  impl_->stopActors(impl_->stopOrder());
  impl_->finish();
}

// ---------------------------------------------------------------- run loop

namespace {

/// Runtime::run() between start and the end of the run, as rounds: wait (simulated clock) for
/// the run to go idle, see whether it ends, then move time to the next timer and fire it. In a
/// deployment the RunCoordinator decides when time moves and when the run ends.
class RunLoop {
 public:
  explicit RunLoop(Runtime::Impl& rt)
      : rt_(rt),
        sim_(rt.clock.kind() == ClockKind::kSimulated),
        coordinator_(rt.options.coordinator),
        limit_(rt.options.max_sim_duration > 0 ? rt.start_sim + rt.options.max_sim_duration
                                               : std::numeric_limits<Nanos>::max()),
        progress_every_(isatty(2) ? kNanosPerSecond / 2 : 5 * kNanosPerSecond),
        last_progress_(steadyNow()) {}

  /// Runs rounds until the run ends; returns why it ended (empty when a stop was requested:
  /// the request carries its own reason).
  std::string run() {
    while (round()) {
    }
    return end_reason_;
  }

 private:
  /// What the coordinator's decision leaves for the rest of a round.
  enum class Next { kEndRun, kNextRound, kFireLocalTimers };

  /// One round; false when the run ends.
  bool round() {
    if (sim_) rt_.waitIdle();
    if (rt_.stop_requested.load()) return false;
    if (coordinator_ != nullptr) {
      const Next next = followCoordinator();
      if (next == Next::kEndRun) return false;
      if (next == Next::kNextRound) return true;
    } else if (localInputsDone()) {
      end_reason_ = "all inputs finished";
      return false;
    }
    showProgress();
    const Nanos due = rt_.nextTimerDue();
    return sim_ ? advanceSimulatedTime(due) : fireWallClockTimers(due);
  }

  /// Every finite source of this process finished and nothing is left to handle.
  bool localInputsDone() const {
    const int finite = rt_.finite_sources.load();
    return finite > 0 && rt_.finished_sources.load() >= finite && rt_.pending.load() == 0;
  }

  RunCoordinator::LocalState localState() {
    RunCoordinator::LocalState s;
    s.next_due = rt_.nextTimerDue();
    s.finite_sources = rt_.finite_sources.load();
    s.finished_sources = rt_.finished_sources.load();
    return s;
  }

  Next followCoordinator() {
    const auto decision =
        sim_ ? coordinator_->idle(
                   localState(),
                   [&] { return rt_.pending.load() != 0 || rt_.stop_requested.load(); })
             : coordinator_->poll(localState(), [&] { return rt_.pending.load() != 0; });
    using V = RunCoordinator::Verdict;
    if (decision.verdict == V::kFinish) {
      end_reason_ = decision.reason;
      if (sim_ && decision.time > rt_.clock.now()) rt_.clock.advanceTo(decision.time);
      return Next::kEndRun;
    }
    if (decision.verdict == V::kStop) {
      rt_.requestStop(decision.reason);
      return Next::kEndRun;
    }
    if (decision.verdict == V::kAdvance) {
      rt_.fireDueTimers(decision.time);
      return Next::kNextRound;
    }
    // kWork: messages arrived. On the simulated clock they run before time may move again;
    // on the wall clock local timers still fire on time.
    return sim_ ? Next::kNextRound : Next::kFireLocalTimers;
  }

  void showProgress() {
    if (rt_.options.show_progress && steadyNow() - last_progress_ >= progress_every_) {
      detail::printProgress(rt_, false);
      last_progress_ = steadyNow();
    }
  }

  /// Simulated clock, run idle: jumps to the next timer (paced by sim_rate) and fires it;
  /// false when no timer is left or the next lies beyond max_duration_s.
  bool advanceSimulatedTime(Nanos due) {
    if (due == detail::Timer::kIdle) {
      end_reason_ = "nothing left to do (no timers, all mailboxes empty)";
      return false;
    }
    if (due > limit_) {
      rt_.clock.advanceTo(limit_);
      end_reason_ = "reached max_duration_s";
      return false;
    }
    if (rt_.options.sim_rate > 0) waitForWallTimeOf(due);
    rt_.fireDueTimers(due);
    return true;
  }

  /// sim_rate pacing: sleeps until the wall time at which simulated time `due` is reached.
  void waitForWallTimeOf(Nanos due) const {
    const auto wall_target =
        rt_.start_wall +
        static_cast<Nanos>(static_cast<double>(due - rt_.start_sim) / rt_.options.sim_rate);
    while (steadyNow() < wall_target && !rt_.stop_requested.load()) {
      std::this_thread::sleep_for(
          std::chrono::nanoseconds(std::min<Nanos>(wall_target - steadyNow(), 20'000'000)));
    }
  }

  /// Wall or paced clock: fires the timers that are due, or waits (at most 20 ms, less when work
  /// ends) for the next one. The run goes on until a stop is requested, its finite inputs are
  /// done, or max_duration_s has passed.
  bool fireWallClockTimers(Nanos due) {
    const Nanos now = rt_.clock.now();
    if (now >= limit_) {
      end_reason_ = "reached max_duration_s";
      return false;
    }
    if (due > now) {
      // A paced clock runs sim_rate times faster than the wall: wait that much less.
      const double rate = rt_.clock.kind() == ClockKind::kPaced && rt_.options.sim_rate > 0
                              ? rt_.options.sim_rate
                              : 1.0;
      const auto wait = static_cast<Nanos>(static_cast<double>(std::min(due, limit_) - now) / rate);
      std::unique_lock lock(rt_.idle_mutex);
      rt_.idle_cv.wait_for(lock, std::chrono::nanoseconds(std::clamp<Nanos>(wait, 0, 20'000'000)));
      return true;
    }
    rt_.fireTimersDueBy(now);
    return true;
  }

  Runtime::Impl& rt_;
  const bool sim_;
  RunCoordinator* const coordinator_;
  const Nanos limit_;
  const Nanos progress_every_;
  Nanos last_progress_;
  std::string end_reason_;
};

}  // namespace

RunReport Runtime::run() {
  auto& rt = *impl_;
  if (rt.options.manual) throw std::logic_error("Runtime::run in manual mode; use step()");
  start();
  const std::string end_reason = RunLoop(rt).run();
  if (rt.stop_requested.load()) {
    std::lock_guard lock(rt.stop_reason_mutex);
    if (rt.stop_reason.empty()) rt.stop_reason = "interrupted (SIGINT/SIGTERM)";
  } else {
    rt.stop_reason = end_reason;
  }
  if (rt.options.show_progress) detail::printProgress(rt, true);
  // Stop sources first; everything they queued is handled before downstream actors stop.
  rt.stopped = true;
  if (rt.options.coordinator == nullptr) {
    rt.stopActors(rt.stopOrder());
  } else {
    rt.stopActorsInTurns(*rt.options.coordinator);
  }
  rt.finish();
  detail::forgetSignalTarget();
  return rt.final_report;
}

}  // namespace tessera
