// The runtime's dedicated executor threads (RuntimeOptions::Executor::kThreadPool): a pool that
// runs actor strands handed to it, and the post-rate estimate that decides whether an idle
// thread polls before sleeping. Internal to tessera_runtime; what a strand is and how it is
// drained lives in mailboxes.cpp. Times in ns of the steady clock.
#pragma once

#include <tessera/runtime/clock.hpp>

#include <atomic>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace tessera::detail {

struct ActorSlot;

/// Whether work is being posted faster than `window` apart on average (a moving average of the
/// intervals between posts): only then is an idle executor thread's poll for the next post
/// likely to pay. Under long handlers (a filter update with its own parallel work) a poll would
/// only take a core from that work. post() needs external locking; steady() may race with it.
class PostRate {
 public:
  explicit PostRate(Nanos window) : window_(window) {}
  void post(Nanos now) {
    const Nanos since = last_ == 0 ? 0 : now - last_;
    last_ = now;
    const Nanos mean = mean_.load(std::memory_order_relaxed);
    mean_.store(mean + (since - mean) / 8, std::memory_order_relaxed);
  }
  bool steady() const { return mean_.load(std::memory_order_relaxed) < window_; }

 private:
  Nanos window_;
  Nanos last_ = 0;
  std::atomic<Nanos> mean_{0};
};

/// Dedicated executor threads: a ready queue of strands; an idle thread sleeps on its own
/// futex word, so waking it costs one futex wake, like a bare hand-off. A strand posted while a
/// thread sleeps is handed to that thread directly (it never enters the ready queue), so the
/// woken thread runs it without touching the pool's lock or queue, whose cache lines would
/// each cross cores on the wake-up path. The most recently idled thread is woken first
/// (LIFO): it is the one whose cache is warm and which, having just run, sits on a core other
/// than a publisher that keeps running. The pool does not own the actors it is handed; they
/// must outlive it.
class StrandPool {
 public:
  StrandPool(int threads, std::function<void(ActorSlot&)> drain);
  ~StrandPool();
  void post(ActorSlot& actor);

 private:
  void loop();
  std::function<void(ActorSlot&)> drain_;
  struct Sleeper {
    std::atomic<std::uint32_t> woken{0};  // futex word: 0 asleep, 1 woken
    ActorSlot* handed = nullptr;          // the strand to run, set before woken; null: quit
  };
  std::mutex mutex_;
  std::deque<ActorSlot*> ready_;
  std::atomic<std::size_t> ready_count_{0};  // ready_.size(), readable without the mutex
  static constexpr Nanos kSpinNanos = 20'000;
  PostRate post_rate_{kSpinNanos};  // posted under mutex_
  std::vector<Sleeper*> sleeping_;  // most recently idled last
  bool quit_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace tessera::detail
