// ShmTransport: topics between processes of one machine over iceoryx shared memory, zero copy.
//
// A publisher on an exported topic loans a chunk, zeroes the part the Cap'n Proto builder may
// use (the message's size hint plus headroom, never the whole chunk) and builds the message in
// place. Subscribers in every importing process read the same chunk through a Message<T> whose
// storage releases the chunk when the last local reader drops it. Chunk layout: a 16-byte
// prefix (magic, sending process, flags) followed by the message in Cap'n Proto's standard
// framing, so a reader needs no copy and no parse beyond the segment table.
//
// Policies across processes: a topic with a reliable subscriber anywhere makes its publishers
// wait for full queues (iceoryx WAIT_FOR_CONSUMER + BLOCK_PRODUCER); keep_latest(n) becomes a
// queue of n that discards the oldest, and those discards are counted.
// A message larger than the largest shared-memory chunk is a MessageError naming the topic,
// never an iceoryx abort. A message that outgrew its loaned chunk (size hint too small) is
// copied once into a larger chunk and counted in `copies`.
//
// Ownership: the transport owns the iceoryx runtime connection, publishers, subscribers and
// the receiving thread; exports and imported messages keep what they need alive through
// shared pointers, so messages may outlive the transport's receive loop (not the process).
#pragma once

#include <tessera/runtime/mailbox.hpp>
#include <tessera/runtime/runtime.hpp>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace tessera {

struct ShmTopic {
  std::string name;
  MessageType type;
  bool exported = false;  // published in this process and read in some process
  bool imported = false;  // read in this process and published in some process
  /// Processes of the deployment that import the topic (each receives every message; for
  /// in-flight counting). 0 for a topic only programs outside the deployment read.
  std::uint32_t importing_processes = 0;
  /// Processes of the deployment that publish it. 0 for a topic only programs outside the
  /// deployment publish (profile `external.inputs`): start-up does not wait for a publisher.
  std::uint32_t publishing_processes = 1;
  bool any_reliable = false;    // some subscriber anywhere is reliable: publishers wait
  MailboxPolicy import_policy;  // this process's strongest subscription to it
  /// Sent and received by this process: its own messages come back through the import.
  bool loopback() const { return exported && imported; }
};

/// Delivery counters of one route (a topic from one process of a deployment to one process that
/// imports it), kept in memory that outlives both ends (the launcher's control block), so that
/// what a SIGKILLed process sent or took is still known: the sender counts each message it
/// published, the receiver each one it took and each one missing from a publisher's numbering
/// while it was subscribed (lost on the way, though both ends were alive).
struct RouteCounters {
  std::atomic<std::uint64_t> sent, received, gaps;
};

/// Where a process's routes count (all may be empty: nothing is counted). `outgoing`: the
/// routes of `topic` from process `from` (one per importing process); `incoming`: the route of
/// `topic` from `from` to `to`, or null.
struct RouteLedger {
  std::function<std::vector<RouteCounters*>(const std::string& topic, std::uint32_t from)> outgoing;
  std::function<RouteCounters*(const std::string& topic, std::uint32_t from, std::uint32_t to)>
      incoming;
};

/// ShmTransportOptions::process_index of a program outside the deployment (`tessera goal`):
/// what it sends is delivered but not counted in flight, since no process counted it as sent.
constexpr std::uint32_t kExternalProcess = 0xffffffffu;

struct ShmTransportOptions {
  std::string runtime_name;         // unique per process incarnation (iceoryx runtime name)
  std::uint32_t process_index = 0;  // written into every chunk this process sends
  std::size_t max_chunk_bytes = 0;  // largest chunk payload RouDi offers
  std::chrono::milliseconds roudi_wait{10000};
  /// Counters for in-flight accounting (may be null): incremented per message sent, times
  /// importing processes; and per message received, after it was queued locally, or known
  /// lost on the way (discarded by a full keep_latest queue, dropped as malformed).
  std::atomic<std::uint64_t>* sent = nullptr;
  std::atomic<std::uint64_t>* received = nullptr;
  /// Called after `received` counted (may be empty): e.g. to wake a process waiting for work.
  std::function<void()> arrived;
  /// Per-route delivery counters (the launcher's ledger), resolved once per topic and sender.
  RouteLedger routes;
};

struct ShmStats {
  std::uint64_t sent = 0, received = 0;
  std::uint64_t copies = 0;          // messages copied into a chunk (did not fit their loan)
  std::uint64_t drops = 0;           // messages a full keep_latest queue discarded
  std::uint64_t heap_fallbacks = 0;  // loans built on the heap (all chunks of a publisher busy)
  std::uint64_t unsent = 0;          // messages not sent after cutOff()
};

class ShmTransport {
 public:
  explicit ShmTransport(ShmTransportOptions options);
  ~ShmTransport();
  ShmTransport(const ShmTransport&) = delete;
  ShmTransport& operator=(const ShmTransport&) = delete;

  /// Creates publishers and subscribers for `topics` and wires them into `runtime`. Call
  /// before runtime.configure().
  void attach(Runtime& runtime, const std::vector<ShmTopic>& topics);
  /// Waits until every import is connected to a publisher (a message sent before that would
  /// not reach this process) and every export has a subscriber; returns false on timeout, or
  /// as soon as `give_up` (when given) returns true. Topics whose peers are all outside the
  /// deployment (publishing_processes or importing_processes 0) are not waited for.
  bool waitForPublishers(std::chrono::milliseconds timeout,
                         const std::function<bool()>& give_up = {});
  /// The topics waitForPublishers() still waits for: imports without a publisher ("'name'
  /// (no publisher)") and exports without a subscriber ("'name' (no subscriber)").
  std::vector<std::string> unconnected() const;
  /// Starts / stops the thread that takes arriving chunks and delivers them.
  void startReceiving();
  void stopReceiving();
  /// Instead of that thread: delivers what arrived on the calling thread, running handlers
  /// here when their actors are idle; waits up to `timeout` only when nothing had arrived. For a
  /// process whose own loop waits for its answers (a request/response client), so that the answer
  /// wakes the thread that asked rather than a second one. Not while the receiving thread runs
  /// (logic_error; startReceiving() afterwards takes over); from one thread at a time.
  void receiveHere(std::chrono::microseconds timeout);
  ShmStats stats() const;
  /// The deployment is gone (its launcher, and RouDi with it, died): from now on nothing is
  /// sent to other processes; a send returns false (the runtime delivers the message to this
  /// process's own subscribers) and is counted in `unsent`. Without RouDi a dead subscriber's
  /// full queue is never removed, so a publisher waiting on it (a reliable topic) would wait for
  /// ever. Any thread.
  void cutOff();

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

/// Bytes of chunk prefix plus segment table in front of a single-segment message.
constexpr std::size_t kShmChunkOverhead = 24;

namespace detail {
/// Chunk reuse without zeroing whole chunks. Every chunk's 16-byte prefix records, with a check
/// value, how far from the payload start its last use may have written ("extent"); past that
/// the chunk is zero. A chunk whose prefix does not check out (fresh memory, or written by
/// something else) counts as written throughout its `capacity`.
///
/// zeroChunkForBuilder: makes bytes [16, end) of the payload zero, touching only what was
/// written before, and records the extent pessimistically (the builder may write up to `end`,
/// the producer without zeroing up to `written_end`; a process that dies while building leaves
/// that). Returns the extent that remains past `end` (0 when the chunk is zero from `end` on),
/// which recordChunkExtent must keep.
std::size_t zeroChunkForBuilder(std::byte* payload, std::size_t capacity, std::size_t end,
                                std::uint32_t origin, std::size_t written_end = 0);
/// The extent the chunk had before this use (for a chunk written without zeroing).
std::size_t chunkExtent(const std::byte* payload, std::size_t capacity);
/// Writes the prefix: Tessera magic, the sending process, the extent and its check value.
void recordChunkExtent(std::byte* payload, std::uint32_t origin, std::size_t extent);

/// In-flight accounting on the receiving side of one topic. A sender counts every message once
/// per importing process, but a keep_latest queue that is full discards its oldest message
/// before the receiving thread takes it (it is busy delivering another topic into a full
/// reliable mailbox, say). iceoryx numbers each publisher port's sends 0, 1, 2, ... and the
/// newest message is never the one discarded, so a gap in the numbers of the messages taken
/// is exactly what was lost (or sent before this process subscribed).
class SendGaps {
 public:
  /// `join_anywhere`: a port's first message taken starts its count wherever its numbering is
  /// (what was sent before this process subscribed is no gap); otherwise ports count from 0.
  explicit SendGaps(bool join_anywhere = false) : join_anywhere_(join_anywhere) {}
  /// The message numbered `sequence` from publisher port `publisher` was taken: returns how
  /// many sent messages it accounts for (1 plus those lost before it).
  std::uint64_t account(std::uint64_t publisher, std::uint64_t sequence);

 private:
  // (port, next expected number), the last port taken from first: a topic has few publishers,
  // and a scan of a short array is cheaper on the delivery path than hashing into a map.
  std::vector<std::pair<std::uint64_t, std::uint64_t>> next_;
  bool join_anywhere_;
};
}  // namespace detail
/// First-segment size used when a publisher gives no size hint.
constexpr std::size_t kShmDefaultMessageBytes = 4096;

}  // namespace tessera
