// Runtime internals: the state behind Runtime (topics, actor slots with their inboxes and
// strands, timers) and the ActorContext an actor configures itself through. Not a public
// header: included by the runtime's sources (wiring.cpp, mailboxes.cpp, run_loop.cpp,
// executor.cpp, metrics.cpp, console.cpp, harness.cpp), the shared-memory transport and the
// executor's unit tests. The runtime owns every ActorSlot (Runtime::Impl::actors) and every
// TopicState (Runtime::Impl::topics); other structures refer to them by index or pointer.
// Times are ns (simulated or steady clock, see clock.hpp).
#pragma once

#include "executor.hpp"
#include "metrics.hpp"

#include <tessera/runtime/options.hpp>
#include <tessera/runtime/profile.hpp>
#include <tessera/runtime/runtime.hpp>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <condition_variable>
#include <deque>
#include <limits>
#include <mutex>
#include <optional>
#include <set>

namespace tessera {

namespace detail {

/// Publisher index of messages published from outside any actor.
constexpr std::uint32_t kExternalOwner = std::numeric_limits<std::uint32_t>::max();

/// Where a topic's messages go: subscription `subscription` of actor slot `actor`.
struct Subscriber {
  std::uint32_t actor;
  std::uint32_t subscription;
};

struct TopicState {
  Runtime::Impl* runtime = nullptr;
  std::string name;
  MessageType type;
  std::vector<Subscriber> subscribers;
  std::vector<std::string> publishers;  // actor names, for error messages
  std::atomic<std::uint64_t> seq{0};
  // Published in this process (not imported), for the report's per-topic figures.
  std::atomic<std::uint64_t> published{0}, published_bytes{0};
  std::shared_ptr<TopicExport> exporter;  // set when the topic leaves this process
};

/// One subscription of an actor: its mailbox policy and handler, and how many of its messages
/// wait in the actor's inbox.
struct Subscription {
  std::string topic;  // global name
  MailboxPolicy policy;
  RawHandler handler;
  std::size_t queued = 0;
  std::uint64_t drops = 0;
  std::uint64_t handled = 0;  // messages its handler ran on (under the strand)
};

/// One queued unit of work: a message for a subscription (index >= 0), or a timer tick
/// (subscription = -(timer index) - 1).
struct Item {
  std::int32_t subscription;
  std::uint64_t order;  // global arrival order, for deterministic manual stepping
  std::shared_ptr<const MessageStorage> message;
  Nanos enqueued = 0;  // steady time it entered the inbox (0: handled without queueing)
};

struct Timer {
  static constexpr Nanos kIdle = std::numeric_limits<Nanos>::max();
  std::uint32_t actor;  // index into Runtime::Impl::actors
  Nanos period;         // 0 = one-shot (callAt): idle (next = kIdle) once fired, then reusable
  Nanos next;
  std::function<void()> callback;
  bool queued = false;  // a tick waits in the inbox: do not queue another
  std::uint64_t overruns = 0;
};

class ActorSlotContext;

/// Everything the runtime keeps for one actor: the instance, its wiring, its inbox (one ordered
/// queue over all its subscriptions and timers), its strand and its metrics.
struct ActorSlot {
  std::uint32_t index = 0;  // in Runtime::Impl::actors
  std::string name;
  std::unique_ptr<Actor> instance;
  std::map<std::string, std::string> remap;
  std::string topic_namespace;  // prefix of the local names not remapped ("" = none)
  std::unique_ptr<ActorSlotContext> context;
  std::vector<Subscription> subscriptions;
  std::vector<std::string> publishes;  // global topic names
  std::vector<std::size_t> timers;     // indices into Impl::timers

  /// The global name of local topic `local`: its remap, else namespaced.
  std::string globalName(const std::string& local) const {
    return globalTopicName(remap, topic_namespace, local);
  }

  // Inbox: one ordered queue over all of this actor's subscriptions and timers.
  std::mutex mutex;
  std::condition_variable space;  // reliable publishers wait here for room
  std::deque<Item> queue;
  std::uint64_t max_depth = 0;
  int waiting_publishers = 0;  // publishers blocked on a full reliable mailbox (under mutex)

  // Strand: `strand` is held by whoever runs this actor's handlers; `scheduled` is true while a
  // drain task waits in the executor, so at most one is ever queued.
  std::mutex strand;
  std::atomic<bool> scheduled{false};

  // Metrics (written under strand or atomically).
  std::atomic<std::uint64_t> messages_in{0}, messages_out{0}, timer_calls{0}, malformed{0};
  DurationHistogram handler_time;
  DurationHistogram queue_wait;  // messages: inbox entry to handler start (0 when run at once)
  std::atomic<std::int64_t> busy_ns{0};  // handler_time's total, readable from other threads

  // Finite-source bookkeeping.
  bool finite = false;
  std::atomic<bool> done{false};
  std::atomic<double> progress{0.0};
};

}  // namespace detail

struct Runtime::Impl {
  explicit Impl(RuntimeOptions o);

  RuntimeOptions options;
  Clock clock;
  std::vector<std::unique_ptr<detail::ActorSlot>> actors;
  std::map<std::string, std::unique_ptr<detail::TopicState>> topics;
  std::mutex timers_mutex;
  std::deque<detail::Timer> timers;  // deque: callAt may add while others run callbacks
  bool configured = false, stopped = false, configuring = false;
  // Read by the shared-memory receive thread, which delivers imports from before start() on.
  std::atomic<bool> started{false};

  // Outstanding work: queued items plus running handlers. Zero means idle.
  std::atomic<std::int64_t> pending{0};
  std::mutex idle_mutex;
  std::condition_variable idle_cv;
  std::atomic<std::uint64_t> order_counter{0};

  std::atomic<bool> stop_requested{false};
  // Every actor stopped: messages still arriving from other processes or hosts are dropped
  // instead of queued (or waited for) where nothing will ever handle them.
  std::atomic<bool> closed{false};
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

  // ---- wiring (wiring.cpp)
  detail::TopicState& topic(const std::string& name, MessageType type, const std::string& who,
                            bool publishing);
  /// Actor indices in stop order: publishers before their subscribers.
  std::vector<std::uint32_t> stopOrder() const;

  // ---- mailboxes and strands (mailboxes.cpp)
  void publish(detail::TopicState* topic, std::uint32_t owner,
               std::shared_ptr<const MessageStorage> message);
  /// Hands `message` to this process's subscribers of `topic`.
  /// Queues `message` (unless null) for the topic's subscribers; see ImportDelivery.
  void deliver(detail::TopicState* topic, std::shared_ptr<const MessageStorage> message,
               ImportDelivery delivery = ImportDelivery::kSchedule);
  void enqueue(detail::ActorSlot& actor, detail::Item item, bool schedule_it = true);
  void schedule(detail::ActorSlot& actor);
  void drainTask(detail::ActorSlot& actor);
  /// Runs up to a budget of `actor`'s items on this thread if nobody else does (then schedules
  /// the rest); false when another thread holds its strand.
  bool drainIfFree(detail::ActorSlot& actor);
  /// Lets go of `actor`'s strand and schedules a drain if items arrived while it was held.
  void releaseStrand(detail::ActorSlot& actor);
  /// Runs `message` on `actor` on this thread at once when its strand is free and its inbox
  /// empty (nothing to keep order with); false, with `message` untouched, otherwise.
  bool runNow(detail::ActorSlot& actor, std::int32_t subscription,
              std::shared_ptr<const MessageStorage>& message);
  /// Runs up to `budget` items of `actor`; caller holds actor.strand.
  std::size_t drainLocked(detail::ActorSlot& actor, std::size_t budget);
  void dispatch(detail::ActorSlot& actor, detail::Item& item);
  void releaseWork(std::size_t n);
  void waitIdle();
  /// Manual mode: runs the item that arrived first of all inboxes; false when all are empty.
  bool stepOne();

  // ---- executor threads (executor.cpp)
  void startExecutor();
  void stopExecutor();

  // ---- timers and the end of a run (run_loop.cpp)
  /// When the earliest timer is due (Timer::kIdle when none is armed): the one scan of the
  /// timers, for the run loop, the deployment and fireDueTimers().
  Nanos nextTimerDue();
  /// Queues a tick of every timer due at or before `now` and re-arms it; a periodic timer that
  /// fell more than a period behind skips the ticks it missed (counted as overruns).
  void fireTimersDueBy(Nanos now);
  /// Runtime::fireDueTimers().
  bool fireDueTimers(Nanos limit);
  void queueTimer(std::size_t index);
  /// Runs queued work until none is left (steps it in manual mode, waits for it otherwise).
  void settle();
  void stopActors(const std::vector<std::uint32_t>& order);
  /// Stops this process's actors in the turns a deployment grants them.
  void stopActorsInTurns(RunCoordinator& coordinator);
  /// After the actors stopped: the final report, and the executor let go.
  void finish();
  void requestStop(const std::string& reason);

  // ---- metrics (metrics.cpp)
  RunReport makeReport() const;
};

namespace detail {

/// The ActorContext of one actor slot: timers, topic wiring (during configure()), progress and
/// stop requests go to the runtime on the actor's behalf.
class ActorSlotContext final : public ActorContext {
 public:
  ActorSlotContext(Runtime::Impl& rt, ActorSlot& actor) : rt_(rt), actor_(actor) {}

  void addTimer(Nanos period, std::function<void()> callback, Nanos first_delay) override;
  void callAt(Nanos when, std::function<void()> callback) override;
  const Clock& clock() const override { return rt_.clock; }
  const std::string& name() const override { return actor_.name; }
  RunSnapshot snapshot() const override;
  const std::string& outputDir() const override { return rt_.options.output_dir; }
  MessageType topicType(std::string_view topic) const override;
  void declareFiniteSource() override;
  void finished() override;
  void reportProgress(double fraction) override;
  void requestStop(std::string_view reason) override;

  std::set<std::string> used_;  // local topic names used, to validate remaps

 protected:
  std::string global(std::string_view local) const;
  void requireConfiguring(const char* what) const;
  void subscribeRaw(std::string_view topic, MessageType type, MailboxPolicy policy,
                    RawHandler handler) override;
  std::pair<TopicState*, std::uint32_t> advertiseRaw(std::string_view topic,
                                                     MessageType type) override;

 private:
  Runtime::Impl& rt_;
  ActorSlot& actor_;
};

// ---- console (console.cpp)
/// One progress line on stderr (rewritten in place on a terminal; `final_line` ends it).
void printProgress(const Runtime::Impl& rt, bool final_line);
/// The progress line's text: with finite sources (fraction: their mean progress, 0-1) a bar,
/// the percentage and, once 1 % is done, the time left at the rate so far; then data and wall
/// seconds and, on a simulated clock, the speed against real time.
std::string formatProgress(double fraction, bool finite, double data_s, double wall_s,
                           bool simulated);
/// The signal handlers of installSignalHandlers() no longer reach any runtime.
void forgetSignalTarget();

}  // namespace detail

}  // namespace tessera
