// Deployment: one profile run as several processes over shared memory (`tessera launch`).
//
// planDeployment() reads the profile's wiring once (every actor configured in a throw-away
// runtime) and decides, per process, which topics leave it (exports), which arrive (imports),
// the order actors stop in (publishers before subscribers, like actors in one process) and
// how much shared memory the topics need. A topic the profile lists under `external:` counts a
// program outside the deployment (`tessera goal`) as one more party, so it crosses shared memory
// even when only one process of the deployment uses it.
//
// The launcher and its worker processes share a small control block (POSIX shared memory,
// mode 0600): each worker reports whether it is idle, its next timer, its inputs and how many
// messages it sent and received; the launcher's DeploymentClock moves simulated time only
// when every worker is idle and every sent message was received (so a multi-process run is
// as deterministic as a single-process one), ends the run when every input finished, and lets
// the processes stop their actors stage by stage in one deployment-wide order (each stage once
// everything the previous one sent was handled). WorkerCoordinator is the worker's side.
#pragma once

#include <tessera/runtime/clock.hpp>
#include <tessera/runtime/profile.hpp>
#include <tessera/runtime/transport.hpp>
#include <tessera/shm/roudi_host.hpp>
#include <tessera/shm/shm_transport.hpp>

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

namespace tessera {

/// Consecutive actors of one process in the deployment's stop order.
struct StopStage {
  int process = 0;  // index in DeploymentPlan::processes
  std::vector<std::string> actors;
};

/// A topic from one process of the deployment to one process that imports it (a process that
/// both publishes and imports a topic has a route to itself).
struct DeliveryRoute {
  std::string topic;
  int from = 0, to = 0;   // indices in DeploymentPlan::processes
  bool reliable = false;  // the importing process reads it reliably (nothing may be dropped)
};

struct DeploymentPlan {
  /// Process names, upstream first; a process's index in this list is its id.
  std::vector<std::string> processes;
  /// Every actor of the deployment in one stop order (publishers before their subscribers, as
  /// in one process), cut where the process changes. With topics both ways between two
  /// processes a process has several stages: its upstream actors stop, then the other
  /// process's, then its downstream ones, so every message sent in stop() is still handled.
  std::vector<StopStage> stop_stages;
  std::map<std::string, std::vector<std::string>> actors;  // process -> actor names
  std::map<std::string, std::vector<ShmTopic>> topics;     // process -> crossing topics
  std::vector<ChunkDemand> demands;                        // shared-memory demand per topic
  /// Every route between processes, by topic then sender then receiver (the delivery ledger's
  /// order: launcher and workers derive the same list from the same profile).
  std::vector<DeliveryRoute> routes;
  /// Actors of other process groups left out of a host's plan: actor -> why (see planDeployment).
  std::map<std::string, std::string> unchecked;
  int indexOf(const std::string& process) const;
};

/// Throws ConfigError for a profile that cannot be deployed (e.g. a restart entry naming no
/// process).
/// With `host` (one host of a deployment over several machines): an actor of another process
/// group whose options fail here (e.g. a dataset folder only the robot has) is left out of the
/// wiring and listed in `unchecked`; topics only it publishes or reads do not cross to `host`.
DeploymentPlan planDeployment(const Profile& profile, const std::string& host = {});

/// Largest message expected on a topic of `type` (bytes), by message family.
std::size_t messageBound(const MessageType& type);

constexpr int kMaxDeploymentProcesses = 32;

/// The control block shared by the launcher and its workers. Plain atomics in shared memory.
struct SyncSlot {
  std::atomic<std::uint64_t> gen;  // bumped on every idle/busy change
  std::atomic<std::uint64_t> idle;
  std::atomic<std::uint64_t> recv_at_idle;
  std::atomic<std::uint64_t> grant_seen;
  std::atomic<std::int64_t> next_due;
  std::atomic<std::int64_t> finite, finished;
  std::atomic<std::uint64_t> sent, received;  // live counters (messages x importing processes)
  std::atomic<std::uint64_t> ready, stopped, wants_stop;
  std::atomic<std::int64_t> pid;  // the worker's process id (a new one per incarnation)
  // The worker's doorbell (a futex word): rung by the launcher when it grants time or ends the
  // run, and by the worker's receiving thread for every message; `waiting` while it sleeps.
  std::atomic<std::uint32_t> bell, waiting;
};
/// What the launcher tells the workers through SyncBlock::command. A 64-bit word, as the field
/// was before it was named: the block's layout and size stay the same, and the zero-filled
/// block a launcher creates reads as kRun.
enum class RunCommand : std::uint64_t {
  kRun = 0,     // the run goes on
  kFinish = 1,  // the run ended normally (inputs finished, time limit): stop in turns
  kStop = 2,    // stop now (a signal, a failed process)
};
static_assert(sizeof(std::atomic<RunCommand>) == sizeof(std::uint64_t) &&
              std::atomic<RunCommand>::is_always_lock_free);

struct SyncBlock {
  std::atomic<std::uint64_t> magic;
  std::atomic<std::uint64_t> go;  // all workers ready: start
  std::atomic<std::uint64_t> grant_seq;
  std::atomic<std::int64_t> grant_time;
  std::atomic<RunCommand> command;
  std::atomic<std::int64_t> end_time;
  std::atomic<std::uint64_t> stop_turn;    // stop stages with index < stop_turn may run
  std::atomic<std::uint64_t> stages_done;  // stop stages finished (their owner sets it)
  char reason[240];
  // The launcher's doorbell: rung by a worker whose slot changed, while the launcher sleeps.
  std::atomic<std::uint32_t> clock_bell, clock_waiting;
  SyncSlot slots[kMaxDeploymentProcesses];
};
// The block is shared between processes built from the same source; the layout is pinned all
// the same, so that a change to it is a deliberate one.
static_assert(sizeof(SyncBlock) == 3896 && offsetof(SyncBlock, command) == 32);

/// The delivery ledger: the counters of the plan's routes (DeploymentPlan::routes, in order; the
/// first kMaxDeliveryRoutes are counted), in the control block's memory, so that they outlive
/// the processes that count them (a SIGKILLed worker's figures are still read at the end).
constexpr int kMaxDeliveryRoutes = 256;
struct DeliveryLedger {
  RouteCounters routes[kMaxDeliveryRoutes];
};

/// Process `process`'s view of the ledger, for ShmTransportOptions::routes.
RouteLedger routeLedger(const DeploymentPlan& plan, DeliveryLedger& ledger);

/// What the ledger says about one route at the end of a run.
struct RouteDelivery {
  DeliveryRoute route;
  std::uint64_t sent = 0, received = 0;
  /// Lost while both ends were alive: a gap in the sender's numbering the receiver saw, or, when
  /// neither end ever died, anything sent and never received.
  std::uint64_t lost_live = 0;
  /// Not received because an end died: sent while the receiver was down, queued at a receiver
  /// that died, or in flight when the sender died. Counted only when an end died.
  std::uint64_t lost_with_dead = 0;
  std::vector<std::string> dead;  // the ends that died at least once
};
/// The ledger read against the plan; `died[i]`: process i died at least once during the run.
std::vector<RouteDelivery> readDelivery(const DeploymentPlan& plan, const DeliveryLedger& ledger,
                                        const std::vector<bool>& died);

/// Doorbells of the control block: futex words shared between processes. ringBell() wakes
/// whoever waits on `bell` (when `waiting` says someone may); waitBell() sleeps until the bell
/// no longer reads `seen`, at most `timeout` (a missed ring only costs that).
void ringBell(std::atomic<std::uint32_t>& bell, const std::atomic<std::uint32_t>& waiting);
void waitBell(std::atomic<std::uint32_t>& bell, std::atomic<std::uint32_t>& waiting,
              std::uint32_t seen, std::chrono::microseconds timeout);

/// Maps (creates when `create`) the control block named `name` ("/tessera_sync_<pid>").
class SyncMemory {
 public:
  SyncMemory(const std::string& name, bool create);
  ~SyncMemory();
  SyncMemory(const SyncMemory&) = delete;
  SyncMemory& operator=(const SyncMemory&) = delete;
  SyncBlock& block() { return *block_; }
  /// The delivery ledger, mapped behind the block (zero when created).
  DeliveryLedger& ledger() { return *ledger_; }
  const std::string& name() const { return name_; }

 private:
  std::string name_;
  bool owner_;
  SyncBlock* block_ = nullptr;
  DeliveryLedger* ledger_ = nullptr;
};

/// A worker's side: implements the runtime's RunCoordinator over its slot.
class WorkerCoordinator final : public RunCoordinator {
 public:
  /// `stages`: the deployment's stop stages (DeploymentPlan::stop_stages).
  WorkerCoordinator(SyncBlock& block, int index, std::vector<StopStage> stages);
  Decision idle(const LocalState& state, const std::function<bool()>& busy) override;
  Decision poll(const LocalState& state, const std::function<bool()>& busy) override;
  std::vector<std::string> awaitStopTurn(const std::function<bool()>& busy) override;
  void stopped() override;
  /// Announces this worker attached and connected, then waits for the launcher's go (false when
  /// the launcher asked to stop instead).
  bool readyAndWait();
  /// True once the deployment ends (the launcher asked to stop or finish, or died): a worker
  /// still starting has nothing left to wait for.
  bool ending();
  SyncSlot& slot() { return block_.slots[index_]; }
  /// True once the launcher died (this process was re-parented).
  bool orphaned();
  /// Called once, on the thread that first finds the launcher dead, before that finding
  /// changes any decision (so before the stop stages it ends): e.g. to cut the transport off.
  void whenOrphaned(std::function<void()> f) { on_orphaned_ = std::move(f); }
  /// A message reached this process (its receiving thread calls this): wakes idle().
  void messageArrived() { ringBell(slot().bell, slot().waiting); }

 private:
  Decision ended() const;
  void publishIdle(bool idle, std::uint64_t received);
  /// Tells the launcher this slot changed.
  void changed() { ringBell(block_.clock_bell, block_.clock_waiting); }
  SyncBlock& block_;
  int index_;
  int launcher_;
  bool orphaned_ = false;
  std::function<void()> on_orphaned_;
  std::uint64_t checks_ = 0;
  std::uint64_t last_grant_ = 0;
  std::vector<StopStage> stages_;
  std::size_t next_stage_ = 0;  // stages before this one are done or not this process's
};

/// The launcher's side of the control block: starts the run once every worker is ready, moves
/// simulated time while the deployment is quiescent, ends the run, and grants the stop stages
/// in turn. step() runs in a loop on one thread; the other methods may be called from another.
class DeploymentClock {
 public:
  /// `stage_owners`: the process of each stop stage (DeploymentPlan::stop_stages); `limit`: the
  /// simulated time at which the run ends.
  DeploymentClock(SyncBlock& block, int processes, std::vector<int> stage_owners, bool sim,
                  double sim_rate, Nanos limit);
  /// One round of the protocol.
  void step();
  /// The process left (it crashed, or exited): the protocol goes on without it. What was sent
  /// to it can no longer be received, so sent and received counts stop having to balance.
  void markGone(int index);
  /// A new incarnation of a gone process is about to start: its slot is reset, so nothing the
  /// old one left there (idle, stopped) is taken for the new one's state.
  void markRestarted(int index);
  /// While stopping: the processes the next stop turn waits for (the owner of an unfinished
  /// stage, or a process still busy), to say so when a stop takes long.
  std::vector<int> holdingUpStop();
  /// Stops the run (RunCommand::kStop) unless it is already ending.
  void requestStop(const std::string& reason);
  std::string reason() const;

 private:
  struct Snapshot {
    std::uint64_t gen, sent, received;
  };
  bool wave(bool running, std::vector<Snapshot>& out, std::uint64_t& sent, std::uint64_t& recv);
  bool quiescent(bool running);
  void issue(RunCommand command, const std::string& reason, Nanos end_time);

  SyncBlock& block_;
  int n_;
  std::vector<int> stage_owners_;
  bool sim_;
  double rate_;
  Nanos limit_;
  Nanos start_wall_ = 0, first_due_ = -1;
  bool gone_[kMaxDeploymentProcesses] = {};
  bool unbalanced_ = false;
  std::mutex mutex_;
};

}  // namespace tessera
