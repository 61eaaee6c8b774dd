// Transport hooks: how a runtime's topics cross its process boundary. The runtime knows no
// transport; the shared-memory transport (shm_transport.hpp) plugs in through these.
//
// Exported topic: every message published on it in this process is built in storage the
// TopicExport loans (a shared-memory chunk) and handed to send(). It is not also delivered
// locally: local subscribers, if any, get it back through this process's import, like every
// other process, so a message is read from the same bytes everywhere.
// Imported topic: messages from outside reach this process's subscribers through the ImportFn
// that Runtime::importTopic returns. It may be called from any thread and blocks while a
// reliable mailbox is full, which is how back-pressure reaches the sender.
//
// Sim-time coordination: a RunCoordinator makes the runtimes of several processes one run —
// simulated time moves only when every process is idle and no message is in flight, and the
// run ends (upstream processes stopping first) when every input of the deployment finished.
#pragma once

#include <tessera/messages/message.hpp>
#include <tessera/runtime/clock.hpp>

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace tessera {

class TopicExport {
 public:
  virtual ~TopicExport() = default;
  /// Storage for one message of about `size_hint_bytes` (0: small), with `blob_bytes` of
  /// uninitialised LoanStorage::blob() beside it.
  virtual std::shared_ptr<detail::LoanStorage> loan(std::size_t size_hint_bytes,
                                                    std::size_t blob_bytes) = 0;
  /// Sends a sealed message (loaned here, or any other storage, which is then copied once).
  /// Returns false when it was not sent (the transport was cut off from the other processes):
  /// the message, and its storage, stay the caller's, and the runtime delivers it to this
  /// process's own subscribers only.
  virtual bool send(const std::shared_ptr<const MessageStorage>& message) = 0;
  /// True when this process imports the topic too: send() comes back through the import, and
  /// the runtime counts the message as pending work until it does.
  virtual bool loopsBack() const = 0;
};

/// How an imported message reaches its subscribers' handlers:
///  kSchedule: an executor thread runs them (the receiving thread only queues);
///  kDefer:    queued only; more messages of the topic follow at once (a batch);
///  kRunHere:  the receiving thread runs the handlers itself when their strands are free, so a
///             message costs one wake-up (the transport's) instead of two. A null message with
///             kRunHere only runs what earlier kDefer calls queued.
enum class ImportDelivery { kSchedule, kDefer, kRunHere };

/// Delivers one message from outside to this process's subscribers. `loopback`: the message was
/// sent by this process (its TopicExport) and is now pending work being returned.
using ImportFn = std::function<void(std::shared_ptr<const MessageStorage> message, bool loopback,
                                    ImportDelivery delivery)>;

class RunCoordinator {
 public:
  virtual ~RunCoordinator() = default;

  struct LocalState {
    Nanos next_due = 0;  // earliest local timer (Nanos max: none)
    int finite_sources = 0;
    int finished_sources = 0;
  };
  enum class Verdict { kWork, kAdvance, kFinish, kStop };
  struct Decision {
    Verdict verdict = Verdict::kWork;
    Nanos time = 0;      // kAdvance: the deployment's new simulated time
    std::string reason;  // kFinish / kStop
  };

  /// Simulated clock: called when this process has nothing queued. Returns kWork as soon as
  /// busy() turns true, kAdvance when the deployment's clock moves, kFinish/kStop at the end.
  virtual Decision idle(const LocalState& state, const std::function<bool()>& busy) = 0;
  /// Wall clock: called about every 20 ms; busy() tells whether work is queued; kWork: go on.
  virtual Decision poll(const LocalState& state, const std::function<bool()>& busy) = 0;
  /// Blocks until this process may stop its next actors and returns their names in stop order.
  /// The deployment stops all actors in one order, publishers before their subscribers across
  /// processes too, so a process may get several turns. Empty: no turn left (every process
  /// has stopped all its actors, or the run must end at once). busy() tells whether messages
  /// still arrive meanwhile.
  virtual std::vector<std::string> awaitStopTurn(const std::function<bool()>& busy) = 0;
  /// The actors of the last turn have stopped and their last messages are sent.
  virtual void stopped() = 0;
};

}  // namespace tessera
