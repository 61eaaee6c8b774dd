// Runtime internals shared by runtime.cpp and harness.cpp. Not a public header.
#pragma once

#include <tessera/runtime/options.hpp>
#include <tessera/runtime/runtime.hpp>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <array>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <limits>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

namespace tessera {

namespace detail {

constexpr std::uint32_t kExternalOwner = std::numeric_limits<std::uint32_t>::max();

struct Subscriber {
  std::uint32_t cell;
  std::uint32_t slot;
};

struct TopicState {
  Runtime::Impl* runtime = nullptr;
  std::string name;
  MessageType type;
  std::vector<Subscriber> subscribers;
  std::vector<std::string> publishers;  // actor names, for error messages
  std::atomic<std::uint64_t> seq{0};
  std::shared_ptr<TopicExport> exporter;  // set when the topic leaves this process
};

/// Log-linear histogram of durations (ns): 8 sub-buckets per power of two, ~6% resolution.
class DurationHistogram {
 public:
  void add(Nanos ns);
  double percentileMicros(double q) const;
  std::uint64_t count() const { return count_; }
  double totalSeconds() const { return static_cast<double>(total_ns_) * 1e-9; }

 private:
  static constexpr int kBuckets = 16 + 60 * 8;
  std::array<std::uint64_t, kBuckets> counts_{};
  std::uint64_t count_ = 0;
  Nanos total_ns_ = 0;
};

struct Slot {
  std::string topic;  // global name
  MailboxPolicy policy;
  RawHandler handler;
  std::size_t queued = 0;
  std::uint64_t drops = 0;
};

/// One queued unit of work: a message for a slot, or a timer tick (slot < 0).
struct Item {
  std::int32_t slot;
  std::uint64_t order;  // global arrival order, for deterministic manual stepping
  std::shared_ptr<const MessageStorage> message;
};

struct Timer {
  static constexpr Nanos kIdle = std::numeric_limits<Nanos>::max();
  std::uint32_t cell;
  Nanos period;  // 0 = one-shot (callAt): idle (next = kIdle) once fired, then reusable
  Nanos next;
  std::function<void()> callback;
  bool queued = false;  // a tick waits in the inbox: do not queue another
  std::uint64_t overruns = 0;
};

class CellContext;

struct Cell {
  std::uint32_t index = 0;
  std::string name;
  std::unique_ptr<Actor> actor;
  std::map<std::string, std::string> remap;
  std::unique_ptr<CellContext> context;
  std::vector<Slot> slots;
  std::vector<std::string> publishes;  // global topic names
  std::vector<std::size_t> timers;     // indices into Impl::timers

  // Inbox: one ordered queue over all of this actor's subscriptions and timers.
  std::mutex mutex;
  std::condition_variable space;  // reliable publishers wait here for room
  std::deque<Item> queue;
  std::uint64_t max_depth = 0;
  int waiting_publishers = 0;  // publishers blocked on a full reliable slot (under mutex)

  // Strand: `strand` is held by whoever runs this actor's handlers; `scheduled` is true while a
  // drain task waits in the executor, so at most one is ever queued.
  std::mutex strand;
  std::atomic<bool> scheduled{false};

  // Metrics (written under strand or atomically).
  std::atomic<std::uint64_t> messages_in{0}, messages_out{0}, timer_calls{0}, malformed{0};
  DurationHistogram handler_time;

  // Finite-source bookkeeping.
  bool finite = false;
  std::atomic<bool> done{false};
  std::atomic<double> progress{0.0};
};

}  // namespace detail

namespace detail {
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
/// than a publisher that keeps running.
class StrandPool {
 public:
  StrandPool(int threads, std::function<void(Cell&)> drain);
  ~StrandPool();
  void post(Cell& cell);

 private:
  void loop();
  std::function<void(Cell&)> drain_;
  struct Sleeper {
    std::atomic<std::uint32_t> woken{0};  // futex word: 0 asleep, 1 woken
    Cell* handed = nullptr;               // the strand to run, set before woken; null: quit
  };
  std::mutex mutex_;
  std::deque<Cell*> ready_;
  std::atomic<std::size_t> ready_count_{0};  // ready_.size(), readable without the mutex
  static constexpr Nanos kSpinNanos = 20'000;
  PostRate post_rate_{kSpinNanos};  // posted under mutex_
  std::vector<Sleeper*> sleeping_;  // most recently idled last
  bool quit_ = false;
  std::vector<std::thread> threads_;
};
}  // namespace detail

struct Runtime::Impl {
  explicit Impl(RuntimeOptions o);

  RuntimeOptions options;
  Clock clock;
  std::vector<std::unique_ptr<detail::Cell>> cells;
  std::map<std::string, std::unique_ptr<detail::TopicState>> topics;
  std::mutex timers_mutex;
  std::deque<detail::Timer> timers;  // deque: callAt may add while others run callbacks
  bool configured = false, started = false, stopped = false, configuring = false;

  // Outstanding work: queued items plus running handlers. Zero means idle.
  std::atomic<std::int64_t> pending{0};
  std::mutex idle_mutex;
  std::condition_variable idle_cv;
  std::atomic<std::uint64_t> order_counter{0};

  std::atomic<bool> stop_requested{false};
  std::string stop_reason;
  std::mutex stop_reason_mutex;
  std::atomic<int> finite_sources{0}, finished_sources{0};

  std::optional<tbb::global_control> parallelism;
  std::optional<tbb::task_arena> arena;
  std::unique_ptr<detail::StrandPool> pool;
  Nanos start_sim = 0;
  Nanos start_wall = 0;
  double start_cpu = 0;
  RunReport final_report;

  detail::TopicState& topic(const std::string& name, MessageType type, const std::string& who,
                            bool publishing);
  void publish(detail::TopicState* topic, std::uint32_t owner,
               std::shared_ptr<const MessageStorage> message);
  /// Hands `message` to this process's subscribers of `topic`.
  /// Queues `message` (unless null) for the topic's subscribers; see ImportDelivery.
  void deliver(detail::TopicState* topic, std::shared_ptr<const MessageStorage> message,
               ImportDelivery delivery = ImportDelivery::kSchedule);
  void enqueue(detail::Cell& cell, detail::Item item, bool schedule_it = true);
  void schedule(detail::Cell& cell);
  void drainTask(detail::Cell& cell);
  /// Runs up to a budget of `cell`'s items on this thread if nobody else does (then schedules
  /// the rest); false when another thread holds its strand.
  bool drainIfFree(detail::Cell& cell);
  /// Lets go of `cell`'s strand and schedules a drain if items arrived while it was held.
  void releaseStrand(detail::Cell& cell);
  /// Runs `message` on `cell` on this thread at once when its strand is free and its inbox
  /// empty (nothing to keep order with); false, with `message` untouched, otherwise.
  bool runNow(detail::Cell& cell, std::int32_t slot,
              std::shared_ptr<const MessageStorage>& message);
  /// Runs up to `budget` items of `cell`; caller holds cell.strand.
  std::size_t drainLocked(detail::Cell& cell, std::size_t budget);
  void dispatch(detail::Cell& cell, detail::Item& item);
  void releaseWork(std::size_t n);
  void waitIdle();
  bool stepOne();
  std::vector<std::uint32_t> stopOrder() const;
  void stopActors(const std::vector<std::uint32_t>& order);
  void queueTimer(std::size_t index);
  RunReport makeReport() const;
  void requestStop(const std::string& reason);
};

namespace detail {
class CellContext final : public ActorContext {
 public:
  CellContext(Runtime::Impl& rt, Cell& cell) : rt_(rt), cell_(cell) {}

  void addTimer(Nanos period, std::function<void()> callback, Nanos first_delay) override {
    if (period <= 0) {
      throw ConfigError("actor '" + cell_.name + "': timer period must be > 0 ns, got " +
                        std::to_string(period));
    }
    std::lock_guard lock(rt_.timers_mutex);
    rt_.timers.push_back(Timer{cell_.index, period,
                               rt_.clock.now() + std::max<Nanos>(first_delay, 0),
                               std::move(callback)});
    cell_.timers.push_back(rt_.timers.size() - 1);
  }
  void callAt(Nanos when, std::function<void()> callback) override {
    std::lock_guard lock(rt_.timers_mutex);
    when = std::max(when, rt_.clock.now());
    for (auto index : cell_.timers) {
      auto& t = rt_.timers[index];
      if (t.period == 0 && t.next == Timer::kIdle && !t.queued && !t.callback) {
        t.next = when;
        t.callback = std::move(callback);
        return;
      }
    }
    rt_.timers.push_back(Timer{cell_.index, 0, when, std::move(callback)});
    cell_.timers.push_back(rt_.timers.size() - 1);
  }
  const Clock& clock() const override { return rt_.clock; }
  const std::string& name() const override { return cell_.name; }
  const std::string& outputDir() const override { return rt_.options.output_dir; }
  MessageType topicType(std::string_view topic) const override {
    auto it = rt_.topics.find(global(topic));
    if (it == rt_.topics.end())
      throw std::logic_error("actor '" + cell_.name + "': no topic '" + std::string(topic) + "'");
    return it->second->type;
  }
  void declareFiniteSource() override {
    if (!cell_.finite) {
      cell_.finite = true;
      ++rt_.finite_sources;
    }
  }
  void finished() override {
    if (cell_.finite && !cell_.done.exchange(true)) {
      cell_.progress = 1.0;
      ++rt_.finished_sources;
    }
  }
  void reportProgress(double fraction) override { cell_.progress = std::clamp(fraction, 0.0, 1.0); }
  void requestStop(std::string_view reason) override {
    rt_.requestStop("actor '" + cell_.name + "': " + std::string(reason));
  }

 protected:
  std::string global(std::string_view local) const {
    auto it = cell_.remap.find(std::string(local));
    return it == cell_.remap.end() ? std::string(local) : it->second;
  }
  void requireConfiguring(const char* what) const {
    if (!rt_.configuring && !rt_.options.manual) {
      throw std::logic_error("actor '" + cell_.name + "': " + what +
                             " is only allowed inside configure()");
    }
  }
  void subscribeRaw(std::string_view topic, MessageType type, MailboxPolicy policy,
                    RawHandler handler) override {
    requireConfiguring("subscribe");
    used_.insert(std::string(topic));
    auto& t = rt_.topic(global(topic), type, cell_.name, false);
    cell_.slots.push_back(Slot{t.name, policy, std::move(handler)});
    t.subscribers.push_back(
        Subscriber{cell_.index, static_cast<std::uint32_t>(cell_.slots.size() - 1)});
  }
  std::pair<TopicState*, std::uint32_t> advertiseRaw(std::string_view topic,
                                                     MessageType type) override {
    requireConfiguring("advertise");
    used_.insert(std::string(topic));
    auto& t = rt_.topic(global(topic), type, cell_.name, true);
    cell_.publishes.push_back(t.name);
    return {&t, cell_.index};
  }

 public:
  std::set<std::string> used_;  // local topic names used, to validate remaps

 private:
  Runtime::Impl& rt_;
  Cell& cell_;
};

}  // namespace detail

}  // namespace tessera
