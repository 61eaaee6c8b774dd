// DdsTransport: topics between hosts over Eclipse Cyclone DDS (docs/architecture.md#several-hosts).
//
// Every topic that crosses hosts is one DDS topic ("tessera/<topic>") of one generic type, a
// Frame holding the message's Cap'n Proto bytes (standard framing), its type id, the sending
// transport and a per-writer sequence number; a topic may be zstd-compressed at a level of its
// own. QoS follows the mailbox policies: a topic with a reliable subscriber anywhere is RELIABLE +
// KEEP_ALL bounded by `reliable_depth` samples (a full reader blocks the writer, which is how
// back-pressure crosses the network), otherwise BEST_EFFORT + KEEP_LAST(depth). The domain id and
// the partition are explicit options: a transport never joins another system's topics by
// accident, and a sample from a foreign partition never matches.
//
// Received samples are checked as shared-memory ones are (size cap before any allocation, Cap'n
// Proto traversal limits, the topic's type id); a bad one is dropped, counted and named once in
// the log. Senders' sequence gaps are counted as losses (expected on best-effort topics only).
//
// Local delivery: a message published on an exported topic reaches this host's own subscribers
// directly (zero copy, in process) and is written to DDS for the other hosts; this host's reader
// ignores its own samples.
//
// Ownership: the transport owns its DDS participant, readers, writers and the receiving thread.
// Delivered messages own copies of their bytes and may outlive the transport.
#pragma once

#include <tessera/runtime/mailbox.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/runtime.hpp>

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace tessera {

/// Profile section `dds:` (each default here).
struct DdsOptions {
  std::uint32_t domain = 0;  ///< DDS domain id (0-230)
  /// DDS partition; required (no default), so two deployments never mix by accident.
  std::string partition;
  /// Network interface name or address to use ("" lets Cyclone choose). "lo" keeps a run on
  /// this machine.
  std::string interface;
  /// Unicast discovery peers (addresses); empty: multicast discovery.
  std::vector<std::string> peers;
  /// Largest message accepted or sent, bytes, before and after decompression.
  std::size_t max_message_bytes = std::size_t{64} << 20;
  /// Reliable topics: samples a reader may hold before the writer blocks.
  std::uint32_t reliable_depth = 64;
  /// Reliable topics: the last samples each writer keeps for a reader that joins late or comes
  /// back after a lost link (a restarted server catches up from them; a returning reader skips
  /// what it already had). 0: none kept. Memory: up to this many samples per reliable topic.
  std::uint32_t replay_depth = 1024;
  /// Seconds without a sign of life after which a host counts as gone (DDS participant lease).
  double lease_s = 10;
  /// A host without inputs of its own waits this long for hosts that vanished without ending
  /// their streams (a lost link or a crash) to come back before it stops, seconds.
  double reconnect_timeout_s = 120;
  /// zstd level per topic (1-19); unlisted topics go uncompressed.
  std::map<std::string, int> compression;
};

/// Reads a profile's `dds:` section (Profile::dds) and validates it; unknown keys, wrong types
/// and values out of range are ConfigErrors naming file, line and key.
DdsOptions loadDdsOptions(const Params& params);

struct DdsTopic {
  std::string name;
  MessageType type;
  bool exported = false;  ///< published on this host, read on another
  bool imported = false;  ///< read on this host, published on another
  bool reliable = true;   ///< some subscriber anywhere is reliable
  /// Best-effort topics: samples kept per reader (keep_latest capacity).
  std::uint32_t depth = 1;
};

struct DdsTopicStats {
  std::uint64_t sent = 0, received = 0;
  std::uint64_t bytes_raw = 0;   ///< sent, before compression (framing bytes)
  std::uint64_t bytes_sent = 0;  ///< sent, payload bytes on DDS
  std::uint64_t lost = 0;        ///< sequence gaps seen by this host's reader
  std::uint64_t duplicates = 0;  ///< replayed samples this host had already (skipped)
  std::uint64_t rejected = 0;    ///< malformed, oversized or foreign-type samples dropped
  double compress_s = 0, decompress_s = 0;
};

struct DdsStats {
  std::map<std::string, DdsTopicStats> topics;
  DdsTopicStats total() const;
};

class DdsTransport {
 public:
  /// `node_name`: this host's part of the deployment, for logs and the participant name.
  DdsTransport(DdsOptions options, std::string node_name);
  ~DdsTransport();
  DdsTransport(const DdsTransport&) = delete;
  DdsTransport& operator=(const DdsTransport&) = delete;

  /// Creates readers and writers for `topics` and wires them into `runtime`; before
  /// runtime.configure().
  void attach(Runtime& runtime, const std::vector<DdsTopic>& topics);
  /// Waits until every import has a matched writer and every export a matched reader; false on
  /// timeout or when `give_up` returns true.
  bool waitForPeers(std::chrono::milliseconds timeout, const std::function<bool()>& give_up = {});
  /// Topics still unmatched: "'name' (no publisher)" / "'name' (no subscriber)".
  std::vector<std::string> unconnected() const;
  /// True once every import had a publisher and none has one now, and every host that sent to
  /// this one ended its streams (flush) or has been gone for dds.reconnect_timeout_s: every host
  /// sending to this one left (false while this host imports nothing).
  bool upstreamLeft();
  /// True while no received sample waits in a reader and the receiving thread is not handing one
  /// to a subscriber. Samples may still be in flight: callers check it over a moment.
  bool drained() const;
  /// Ends this host's streams: an end mark on every exported topic, then waits until every
  /// reliable sample this host wrote is acknowledged by the readers on the other hosts (call it
  /// before leaving: Cyclone lingers only about a second for them). Returns the topics still
  /// unacknowledged at `timeout`.
  std::vector<std::string> flush(std::chrono::milliseconds timeout);
  void startReceiving();
  void stopReceiving();
  DdsStats stats() const;

  /// Cyclone's configuration XML for `options` (interface, peers, sample size cap).
  static std::string configXml(const DdsOptions& options);
  /// Checks options (domain range, partition given, levels 1-19); ConfigError naming the key.
  static void validate(const DdsOptions& options);

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

namespace detail {
/// zstd of `bytes` at `level`; frame bytes of a message to send.
std::vector<std::byte> zstdCompress(std::span<const std::byte> bytes, int level);
/// Decompresses a zstd frame that claims `raw_bytes`; MessageError when that exceeds `cap`,
/// disagrees with the frame, or the data is corrupt. `what` names the source.
std::vector<std::byte> zstdDecompress(std::span<const std::byte> bytes, std::size_t raw_bytes,
                                      std::size_t cap, const std::string& what);
/// Decompresses a zstd frame into `out`, which must be exactly the frame's content size.
void zstdDecompressInto(std::span<const std::byte> bytes, std::span<std::byte> out,
                        const std::string& what);
}  // namespace detail

}  // namespace tessera
