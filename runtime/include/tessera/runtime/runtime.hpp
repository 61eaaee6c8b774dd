// Runtime: owns the actors of one process, the topics between them (the in-process transport:
// fan-out shares one immutable message, zero copy), the clock and the executor.
//
// Two ways to drive it:
//  * run(): actors run on the executor (a thread pool, or a TBB task arena); each actor is a
//    strand (one handler at a time).
//    With a simulated clock, time jumps to the next timer once every mailbox is empty and no
//    handler runs, so runs are deterministic and as fast as the CPU allows (or paced by
//    sim_rate). With a wall clock, timers fire on time until stop is requested.
//  * manual mode (tests, ActorHarness): no threads; the caller steps items and timers.
#pragma once

#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/transport.hpp>

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace tessera {

struct RuntimeOptions {
  ClockKind clock = ClockKind::kSimulated;
  Nanos sim_start = 0;
  /// Simulated clock only: 0 runs as fast as possible, 1.0 paces at real time, 2.0 twice as fast.
  double sim_rate = 0.0;
  /// Where actors write files; "" for none.
  std::string output_dir;
  /// Executor threads; 0 = one with a simulated clock (a repeatable run: time waits for every
  /// handler anyway, so more threads would only reorder one instant's messages), every core
  /// with a wall or paced clock.
  int threads = 0;
  /// Who runs the actors' strands. kThreadPool: dedicated threads woken by a condition variable
  /// (measured wake-up close to a bare hand-off). kTbbArena: tasks enqueued on a TBB task_arena
  /// (slower wake-up on this VM, see `tessera bench runtime`). Either way, handlers use TBB's
  /// parallel algorithms for data-parallel work.
  enum class Executor { kThreadPool, kTbbArena };
  Executor executor = Executor::kThreadPool;
  /// Print progress of finite sources to stderr about once a second.
  bool show_progress = true;
  /// Stop after this much simulated time (0: no limit).
  Nanos max_sim_duration = 0;
  /// No executor threads: the caller drives the run with step()/fireDueTimers().
  bool manual = false;
  /// Part of a multi-process deployment: time and the end of the run are decided together
  /// (see transport.hpp). Not owned; must outlive run().
  RunCoordinator* coordinator = nullptr;
  /// Topics published from outside (a program joining a deployment, profile `external.inputs`):
  /// configure() does not require a publisher for them.
  std::vector<std::string> external_inputs;
};

/// Per-actor figures printed at exit and stored in summary.json.
/// One subscription of an actor: its global topic, whether its mailbox is reliable (never
/// drops; publishers wait) or keep_latest (evicts the oldest), messages handled and evicted.
struct SubscriptionReport {
  std::string topic;
  bool reliable = true;
  std::uint64_t handled = 0, drops = 0;
};

struct ActorReport {
  std::string name;
  std::uint64_t messages_in = 0;   // handled messages
  std::uint64_t messages_out = 0;  // published messages
  std::uint64_t timer_calls = 0;
  std::uint64_t drops = 0;      // keep_latest evictions, all subscriptions
  std::uint64_t malformed = 0;  // delivered messages that could not be read (dropped)
  std::uint64_t max_queue_depth = 0;
  double handler_p50_us = 0, handler_p99_us = 0, handler_total_s = 0;
  /// Time messages waited in the inbox before their handler started (0 for those handled at once).
  double queue_wait_p50_us = 0, queue_wait_p99_us = 0;
  std::vector<SubscriptionReport> subscriptions;
  Summary summary;  // the actor's own figures
};

/// A topic's messages published in this process (imports from other processes not counted);
/// bytes are the messages' Cap'n Proto segments.
struct TopicReport {
  std::string name;
  std::uint64_t messages = 0, bytes = 0;
};

struct RunReport {
  double wall_s = 0, cpu_s = 0;
  double sim_duration_s = 0;  // data / simulated time covered
  double peak_rss_mb = 0;
  bool interrupted = false;  // stopped by a signal or requestStop
  std::string stop_reason;
  std::vector<ActorReport> actors;
  std::vector<TopicReport> topics;  // those published in this process, by name
  std::string table() const;        // human-readable metrics table
};

class Runtime {
 public:
  explicit Runtime(RuntimeOptions options = {});
  ~Runtime();
  Runtime(const Runtime&) = delete;
  Runtime& operator=(const Runtime&) = delete;

  /// Adds an actor instance. `remap` maps the actor's local topic names to global ones; a local
  /// name not remapped becomes "topic_namespace/name" when topic_namespace is not empty (one
  /// robot's actors among several robots'), else stays as it is.
  Actor& add(std::string name, std::unique_ptr<Actor> actor,
             std::map<std::string, std::string> remap = {}, std::string topic_namespace = {});

  /// A publisher from outside any actor (tests, benchmarks, bridges). Call before configure().
  template <typename T>
  Publisher<T> externalPublisher(const std::string& topic) {
    auto [state, owner] = externalAdvertise(topic, messageTypeOf<T>());
    return Publisher<T>(state, owner);
  }

  /// Cross-process topics (see transport.hpp). Call before configure().
  void exportTopic(const std::string& topic, MessageType type, std::shared_ptr<TopicExport> out);
  ImportFn importTopic(const std::string& topic, MessageType type);

  /// Configures every actor and checks the wiring: one message type per topic, and every
  /// subscribed topic has a publisher (unless allow_unpublished, or the topic is one of
  /// RuntimeOptions::external_inputs). Throws ConfigError.
  void configure(bool allow_unpublished = false);

  /// Starts, runs until every finite source finished (or stop was requested, or the simulated
  /// time limit), drains, stops actors upstream-first, and reports.
  RunReport run();

  /// Thread-safe and async-signal-safe: ask a running run() to stop cleanly.
  void requestStop();
  /// Installs signal handlers that call requestStop() on this runtime: the first SIGINT/SIGTERM
  /// stops cleanly and a second exits at once (no outputs); any number of SIGHUPs (a hung-up
  /// terminal, a launcher's death) only stop cleanly.
  void installSignalHandlers();

  // ---- manual mode ----
  void start();
  /// Handles one queued item (deterministic order); false when all mailboxes are empty.
  bool step();
  std::size_t runUntilIdle();
  /// Advances the simulated clock to the earliest timer due at or before `limit`, queues every
  /// timer due then, and returns true; false (time set to limit) when none is due.
  bool fireDueTimers(Nanos limit);
  void stop();
  RunReport report() const;

  const Clock& clock() const;
  /// Global name of actor `actor`'s local topic.
  std::string globalTopic(const std::string& actor, const std::string& local) const;
  /// Topics an actor subscribes to / publishes (global names), after configure().
  std::vector<std::string> subscriptionsOf(const std::string& actor) const;
  std::vector<std::string> publicationsOf(const std::string& actor) const;
  /// Actor names in the order they stop (publishers before their subscribers, cycles broken by
  /// registration order), after configure().
  std::vector<std::string> stopOrder() const;
  std::vector<std::string> topicsOfType(MessageType type) const;
  /// Actors that declared a finite input (after configure()).
  int finiteSources() const;
  /// Message type a topic carries (after configure()); throws for an unknown topic.
  MessageType topicType(const std::string& topic) const;
  /// Mailbox policy of `actor`'s subscription to global `topic`.
  MailboxPolicy subscriptionPolicy(const std::string& actor, const std::string& topic) const;

  struct Impl;

 private:
  friend class ActorHarness;
  std::pair<detail::TopicState*, std::uint32_t> externalAdvertise(const std::string& topic,
                                                                  MessageType type);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
