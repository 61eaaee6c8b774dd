// The executor: the dedicated strand pool's threads, and starting and stopping whichever
// executor RuntimeOptions chose (the pool, or a TBB task arena).
#include "runtime_impl.hpp"

#include <pthread.h>

#include <algorithm>
#include <string>

namespace tessera {
namespace detail {

StrandPool::StrandPool(int threads, std::function<void(ActorSlot&)> drain)
    : drain_(std::move(drain)) {
  for (int i = 0; i < threads; ++i) {
    threads_.emplace_back([this, i] {
      // Named so that top -H, gdb and perf sched show which thread is the pool's.
      pthread_setname_np(pthread_self(), ("tessera-pool-" + std::to_string(i)).c_str());
      loop();
    });
  }
}

StrandPool::~StrandPool() {
  std::vector<Sleeper*> wake;
  {
    std::lock_guard lock(mutex_);
    quit_ = true;
    wake.swap(sleeping_);
  }
  for (Sleeper* s : wake) {
    s->handed = nullptr;
    s->woken.store(1, std::memory_order_release);
    s->woken.notify_one();
  }
  for (auto& t : threads_) t.join();
}

void StrandPool::post(ActorSlot& actor) {
  Sleeper* wake = nullptr;
  {
    std::lock_guard lock(mutex_);
    post_rate_.post(steadyNow());
    if (sleeping_.empty()) {
      ready_.push_back(&actor);
      ready_count_.store(ready_.size(), std::memory_order_release);
    } else {
      wake = sleeping_.back();
      sleeping_.pop_back();
    }
  }
  if (wake) {
    wake->handed = &actor;
    wake->woken.store(1, std::memory_order_release);
    wake->woken.notify_one();
  }
}

void StrandPool::loop() {
  Sleeper self;
  std::unique_lock lock(mutex_);
  while (true) {
    if (ready_.empty()) {
      if (quit_) return;
      // Under a steady stream the next strand arrives within microseconds: poll briefly before
      // paying for a futex sleep and wake-up (yielding, so a publisher on this core still runs).
      lock.unlock();
      const Nanos spin_until = steadyNow() + (post_rate_.steady() ? kSpinNanos : 0);
      while (ready_count_.load(std::memory_order_acquire) == 0 && steadyNow() < spin_until) {
        std::this_thread::yield();
      }
      lock.lock();
      if (!ready_.empty() || quit_) continue;
      self.woken.store(0, std::memory_order_relaxed);
      sleeping_.push_back(&self);
      lock.unlock();
      while (self.woken.load(std::memory_order_acquire) == 0) self.woken.wait(0);
      if (self.handed == nullptr) return;  // the pool is shutting down
      drain_(*self.handed);
      lock.lock();
      continue;
    }
    ActorSlot* actor = ready_.front();
    ready_.pop_front();
    ready_count_.store(ready_.size(), std::memory_order_release);
    lock.unlock();
    drain_(*actor);
    lock.lock();
  }
}

}  // namespace detail

void Runtime::Impl::startExecutor() {
  // With a simulated clock, time waits for every handler, so a second executor thread only
  // overlaps handlers of the same instant, and then the order in which an actor sees that
  // instant's messages (a scan against the optimiser's answer to the last one) depends on thread
  // timing: the run is no longer repeatable (docs/architecture.md#runtime). Handlers keep TBB's
  // workers for their own parallel work either way.
  const int threads = options.threads > 0 ? options.threads
                      : options.clock == ClockKind::kSimulated
                          ? 1
                          : static_cast<int>(std::max(2u, std::thread::hardware_concurrency()));
  if (options.executor == RuntimeOptions::Executor::kThreadPool) {
    pool = std::make_unique<detail::StrandPool>(
        threads, [this](detail::ActorSlot& actor) { drainTask(actor); });
  } else {
    // The arena's threads are all TBB workers (the caller only waits), so lift TBB's default
    // limit of one worker per core minus the calling thread.
    parallelism.emplace(tbb::global_control::max_allowed_parallelism,
                        static_cast<std::size_t>(threads) + 1);
    arena.emplace(threads, 0);
  }
}

void Runtime::Impl::stopExecutor() {
  pool.reset();
  arena.reset();
  parallelism.reset();
}

}  // namespace tessera
