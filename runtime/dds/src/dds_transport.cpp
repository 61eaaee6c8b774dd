// DdsTransport over Cyclone DDS's C API (dds.h); see dds_transport.hpp.
#include <tessera/dds/dds_transport.hpp>
#include <tessera/runtime/options.hpp>

#include "tessera_frame.h"

#include <dds/dds.h>
#include <yaml-cpp/yaml.h>
#include <zstd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <optional>
#include <random>
#include <set>
#include <thread>

namespace tessera {

namespace detail {

std::vector<std::byte> zstdCompress(std::span<const std::byte> bytes, int level) {
  std::vector<std::byte> out(ZSTD_compressBound(bytes.size()));
  const std::size_t n = ZSTD_compress(out.data(), out.size(), bytes.data(), bytes.size(), level);
  if (ZSTD_isError(n)) {
    throw MessageError(std::string("zstd compression failed: ") + ZSTD_getErrorName(n));
  }
  out.resize(n);
  return out;
}

void zstdDecompressInto(std::span<const std::byte> bytes, std::span<std::byte> out,
                        const std::string& what) {
  const std::size_t raw_bytes = out.size();
  const unsigned long long framed = ZSTD_getFrameContentSize(bytes.data(), bytes.size());
  if (framed == ZSTD_CONTENTSIZE_ERROR || framed == ZSTD_CONTENTSIZE_UNKNOWN) {
    throw MessageError(what + ": not a zstd frame with a content size");
  }
  if (framed != raw_bytes) {
    throw MessageError(what + ": zstd frame holds " + std::to_string(framed) +
                       " bytes, the sample says " + std::to_string(raw_bytes));
  }
  const std::size_t n = ZSTD_decompress(out.data(), out.size(), bytes.data(), bytes.size());
  if (ZSTD_isError(n) || n != raw_bytes) {
    throw MessageError(what + ": corrupt zstd data" +
                       (ZSTD_isError(n) ? std::string(": ") + ZSTD_getErrorName(n) : ""));
  }
}

std::vector<std::byte> zstdDecompress(std::span<const std::byte> bytes, std::size_t raw_bytes,
                                      std::size_t cap, const std::string& what) {
  if (raw_bytes > cap) {
    throw MessageError(what + ": claims " + std::to_string(raw_bytes) +
                       " bytes uncompressed, more than the limit of " + std::to_string(cap));
  }
  std::vector<std::byte> out(raw_bytes);
  zstdDecompressInto(bytes, out, what);
  return out;
}

}  // namespace detail

DdsTopicStats DdsStats::total() const {
  DdsTopicStats t;
  for (const auto& [name, s] : topics) {
    t.sent += s.sent;
    t.received += s.received;
    t.bytes_raw += s.bytes_raw;
    t.bytes_sent += s.bytes_sent;
    t.lost += s.lost;
    t.rejected += s.rejected;
    t.duplicates += s.duplicates;
    t.compress_s += s.compress_s;
    t.decompress_s += s.decompress_s;
  }
  return t;
}

namespace dds_detail {

constexpr std::uint8_t kCodecRaw = 0;
constexpr std::uint8_t kCodecZstd = 1;
/// The message's only segment, without the segment table: written to DDS from the message's
/// own memory (no framing copy on the sending side).
constexpr std::uint8_t kCodecSegment = 2;
/// No message: the writer's stream ends here (its host leaves on purpose; see flush()).
constexpr std::uint8_t kCodecEnd = 3;

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// DDS topic name of a Tessera topic: "tessera/" + the name, characters DDS does not take in a
/// topic name replaced by '_'.
std::string ddsTopicName(const std::string& topic) {
  std::string out = "tessera/";
  for (char c : topic) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '/';
    out.push_back(ok ? c : '_');
  }
  return out;
}

std::string ddsError(dds_return_t rc) {
  return std::string(dds_strretcode(rc));
}

/// One Cyclone domain per domain id per process, shared by every transport in it (tests run
/// several): created with the first transport's configuration, deleted with the last one.
class DomainRegistry {
 public:
  static DomainRegistry& instance() {
    static DomainRegistry r;
    return r;
  }
  void acquire(std::uint32_t domain, const std::string& xml) {
    std::lock_guard lock(mutex_);
    auto& e = domains_[domain];
    if (e.refs++ > 0) return;
    const dds_entity_t d = dds_create_domain(domain, xml.c_str());
    if (d < 0) {
      --e.refs;
      throw ConfigError("dds: cannot create DDS domain " + std::to_string(domain) + ": " +
                        ddsError(d) + " (check dds.interface and dds.peers)");
    }
    e.handle = d;
  }
  void release(std::uint32_t domain) {
    std::lock_guard lock(mutex_);
    auto it = domains_.find(domain);
    if (it == domains_.end() || --it->second.refs > 0) return;
    dds_delete(it->second.handle);
    domains_.erase(it);
  }

 private:
  struct Entry {
    int refs = 0;
    dds_entity_t handle = 0;
  };
  std::mutex mutex_;
  std::map<std::uint32_t, Entry> domains_;
};

/// Received messages of 64 KiB and more are copied into buffers from this pool rather than into
/// fresh memory: a fresh large buffer is a fresh mapping whose page faults cost more than the
/// copy (measured with `tessera bench dds`: 1 MiB latency 2.5x raw DDS's with fresh buffers).
/// Power-of-two classes, a few free buffers kept per class; process-wide and never destroyed,
/// since messages may outlive every transport.
class WordPool final : public kj::ArrayDisposer {
 public:
  static constexpr std::size_t kMinWords = std::size_t{8} << 10;  // 64 KiB
  static constexpr std::size_t kKeep = 4;

  static const WordPool& instance() {
    static const WordPool* pool = new WordPool;
    return *pool;
  }
  kj::Array<capnp::word> take(std::size_t words) const {
    if (words < kMinWords) return kj::heapArray<capnp::word>(words);
    const std::size_t cls = classOf(words);
    capnp::word* buffer = nullptr;
    {
      std::lock_guard lock(mutex_);
      auto& free = free_[cls];
      if (!free.empty()) {
        buffer = free.back();
        free.pop_back();
      }
    }
    if (buffer == nullptr) buffer = new capnp::word[std::size_t{1} << cls];
    return kj::Array<capnp::word>(buffer, words, *this);
  }

 private:
  static std::size_t classOf(std::size_t words) {
    std::size_t cls = 0;
    while ((std::size_t{1} << cls) < words) ++cls;
    return cls;
  }
  void disposeImpl(void* first, std::size_t, std::size_t count, std::size_t,
                   void (*)(void*)) const override {
    auto* buffer = static_cast<capnp::word*>(first);
    {
      std::lock_guard lock(mutex_);
      auto& free = free_[classOf(count)];
      if (free.size() < kKeep) {
        free.push_back(buffer);
        return;
      }
    }
    delete[] buffer;
  }
  mutable std::mutex mutex_;
  mutable std::map<std::size_t, std::vector<capnp::word*>> free_;
};

struct Counters {
  std::atomic<std::uint64_t> sent{0}, received{0}, bytes_raw{0}, bytes_sent{0}, lost{0},
      rejected{0}, duplicates{0};
  std::atomic<std::uint64_t> compress_ns{0}, decompress_ns{0};
};

}  // namespace dds_detail

using namespace dds_detail;

struct DdsTransport::Impl {
  DdsOptions options;
  std::string node;
  std::uint64_t origin = 0;
  dds_entity_t participant = 0, publisher = 0, subscriber = 0, waitset = 0;
  std::atomic<bool> stopping{false};
  std::atomic<bool> taking{false};  // the receiving thread is taking or delivering samples
  // Senders (transport ids) seen on any import, and those that ended their streams.
  std::mutex origins_mutex;
  std::set<std::uint64_t> seen_origins, ended_origins;
  // When the imports last lost their last publisher (upstreamLeft's reconnect timeout).
  std::optional<std::chrono::steady_clock::time_point> gone_since;
  std::thread receiver;

  struct Export;
  struct Import {
    DdsTopic topic;
    dds_entity_t reader = 0, condition = 0;
    ImportFn deliver;
    std::map<std::uint64_t, std::uint64_t> next_seq;  // origin -> expected sequence
    bool warned = false;
    Counters* counters = nullptr;
  };
  std::vector<std::shared_ptr<Export>> exports;
  std::vector<std::unique_ptr<Import>> imports;
  std::map<std::string, std::unique_ptr<Counters>> counters;
  std::map<std::string, dds_entity_t> topics;  // DDS topic entities by Tessera name

  Counters& countersFor(const std::string& name) {
    auto& c = counters[name];
    if (!c) c = std::make_unique<Counters>();
    return *c;
  }
  dds_entity_t topicEntity(const std::string& name) {
    auto it = topics.find(name);
    if (it != topics.end()) return it->second;
    const dds_entity_t t = dds_create_topic(participant, &tessera_dds_Frame_desc,
                                            ddsTopicName(name).c_str(), nullptr, nullptr);
    if (t < 0) {
      throw ConfigError("dds: cannot create topic '" + name + "': " + ddsError(t));
    }
    topics[name] = t;
    return t;
  }
  void takeAll(Import& import);
};

struct DdsTransport::Impl::Export final : TopicExport {
  Impl* impl = nullptr;
  DdsTopic topic;
  dds_entity_t writer = 0;
  ImportFn local;  // this host's own subscribers
  int level = 0;
  Counters* counters = nullptr;
  std::mutex mutex;  // sequence numbers and the write itself stay in order
  std::uint64_t seq = 0;
  std::vector<std::byte> framed;  // the last message's framing (reused)

  std::shared_ptr<detail::LoanStorage> loan(std::size_t size_hint_bytes,
                                            std::size_t blob_bytes) override {
    return detail::makeBuilderStorage(size_hint_bytes, blob_bytes);
  }
  bool loopsBack() const override { return false; }

  bool send(const std::shared_ptr<const MessageStorage>& message) override {
    // Local subscribers first, straight from the publisher's storage.
    local(message, false, ImportDelivery::kSchedule);

    const auto segments = message->segments();
    const std::size_t table_words = segments.size() / 2 + 1;
    std::size_t bytes = table_words * sizeof(capnp::word);
    for (const auto& s : segments) bytes += s.size() * sizeof(capnp::word);
    if (bytes > impl->options.max_message_bytes) {
      throw MessageError("dds: topic '" + topic.name + "': a message of " + std::to_string(bytes) +
                         " bytes exceeds dds.max_message_bytes (" +
                         std::to_string(impl->options.max_message_bytes) + ")");
    }
    std::lock_guard lock(mutex);
    if (level == 0 && segments.size() == 1) {
      const auto segment = std::as_bytes(std::span(segments[0].begin(), segments[0].size()));
      write(kCodecSegment, segment, segment.size());
      counted(bytes, segment.size());
      return true;
    }
    // The framing is built in a buffer kept by the export (under its lock): a fresh one per
    // message costs page faults on every large message.
    if (framed.size() < bytes) framed.resize(bytes);
    {
      auto* table = reinterpret_cast<std::uint32_t*>(framed.data());
      std::memset(framed.data(), 0, table_words * sizeof(capnp::word));
      table[0] = static_cast<std::uint32_t>(segments.size() - 1);
      std::size_t at = table_words * sizeof(capnp::word);
      for (std::size_t i = 0; i < segments.size(); ++i) {
        table[i + 1] = static_cast<std::uint32_t>(segments[i].size());
        std::memcpy(framed.data() + at, segments[i].begin(),
                    segments[i].size() * sizeof(capnp::word));
        at += segments[i].size() * sizeof(capnp::word);
      }
    }
    const std::span<const std::byte> raw(framed.data(), bytes);
    std::vector<std::byte> packed;
    if (level > 0) {
      const auto t0 = std::chrono::steady_clock::now();
      packed = detail::zstdCompress(raw, level);
      counters->compress_ns += static_cast<std::uint64_t>(secondsSince(t0) * 1e9);
    }
    const std::span<const std::byte> payload = level > 0 ? std::span<const std::byte>(packed) : raw;
    write(level > 0 ? kCodecZstd : kCodecRaw, payload, bytes);
    counted(bytes, payload.size());
    return true;
  }

  /// Ends the stream: a sample without a message, after the last one.
  void end() {
    std::lock_guard lock(mutex);
    write(kCodecEnd, {}, 0);
  }

  /// One message sent: `bytes` of framing, `wire` bytes of payload on DDS.
  void counted(std::size_t bytes, std::size_t wire) {
    counters->sent += 1;
    counters->bytes_raw += bytes;
    counters->bytes_sent += wire;
  }

  /// Writes one sample, the next in this writer's sequence (under `mutex`): `raw_bytes` is what
  /// the payload decodes to.
  void write(std::uint8_t codec, std::span<const std::byte> payload, std::size_t raw_bytes) {
    tessera_dds_Frame sample{};
    sample.type_id = topic.type.id;
    sample.origin = impl->origin;
    sample.seq = seq;
    sample.codec = codec;
    sample.raw_bytes = static_cast<std::uint32_t>(raw_bytes);
    sample.payload._buffer =
        const_cast<std::uint8_t*>(reinterpret_cast<const std::uint8_t*>(payload.data()));
    sample.payload._length = static_cast<std::uint32_t>(payload.size());
    sample.payload._maximum = sample.payload._length;
    sample.payload._release = false;
    const auto start = std::chrono::steady_clock::now();
    auto last_warning = start;
    for (;;) {
      const dds_return_t rc = dds_write(writer, &sample);
      if (rc == DDS_RETCODE_OK) break;
      if (rc == DDS_RETCODE_TIMEOUT && !impl->stopping.load()) {
        // A reliable reader on another host is full: wait for it (back-pressure), and say so.
        if (secondsSince(last_warning) >= 10) {
          last_warning = std::chrono::steady_clock::now();
          std::fprintf(stderr,
                       "warning: dds: topic '%s': waiting %.0f s for a reader on another host "
                       "to take samples\n",
                       topic.name.c_str(), secondsSince(start));
        }
        continue;
      }
      throw MessageError("dds: topic '" + topic.name + "': write failed: " + ddsError(rc));
    }
    ++seq;
  }
};

void DdsTransport::Impl::takeAll(Import& import) {
  constexpr std::uint32_t kBatch = 16;
  void* samples[kBatch] = {};
  dds_sample_info_t infos[kBatch];
  for (;;) {
    samples[0] = nullptr;  // loan from the reader
    const dds_return_t n = dds_take(import.reader, samples, infos, kBatch, kBatch);
    if (n <= 0) return;
    for (dds_return_t i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* f = static_cast<const tessera_dds_Frame*>(samples[i]);
      char peer[24];
      std::snprintf(peer, sizeof peer, "%016llx", static_cast<unsigned long long>(f->origin));
      const std::string what = "dds: topic '" + import.topic.name + "', sample from peer " + peer;
      try {
        if (f->type_id != import.topic.type.id) {
          char id[32];
          std::snprintf(id, sizeof id, "%016llx", static_cast<unsigned long long>(f->type_id));
          throw MessageError(what + ": a sample of type id " + id + ", expected " +
                             import.topic.type.name);
        }
        // Gaps in a sender's numbers are samples that never arrived; numbers already seen are
        // replays after a lost link (the writer keeps its last samples for returning readers).
        const auto [slot, new_sender] = import.next_seq.try_emplace(f->origin, f->seq);
        if (new_sender) {
          std::lock_guard lock(origins_mutex);
          seen_origins.insert(f->origin);
        }
        auto& next = slot->second;
        if (f->seq < next) {
          import.counters->duplicates += 1;
          continue;
        }
        if (f->seq > next) import.counters->lost += f->seq - next;
        next = f->seq + 1;
        if (f->codec == kCodecEnd) {
          std::lock_guard lock(origins_mutex);
          ended_origins.insert(f->origin);
          continue;
        }

        const std::span<const std::byte> payload(
            reinterpret_cast<const std::byte*>(f->payload._buffer), f->payload._length);
        DecodeLimits limits;
        limits.max_bytes = options.max_message_bytes;
        if (f->raw_bytes == 0 || f->raw_bytes % sizeof(capnp::word) != 0 ||
            f->raw_bytes > options.max_message_bytes) {
          throw MessageError(what + ": a message of " + std::to_string(f->raw_bytes) +
                             " bytes; expected whole 8-byte words, at most " +
                             std::to_string(options.max_message_bytes));
        }
        kj::Array<capnp::word> words;
        if (f->codec == kCodecZstd) {
          const auto t0 = std::chrono::steady_clock::now();
          words = WordPool::instance().take(f->raw_bytes / sizeof(capnp::word));
          detail::zstdDecompressInto(
              payload, std::as_writable_bytes(std::span(words.begin(), words.size())), what);
          import.counters->decompress_ns += static_cast<std::uint64_t>(secondsSince(t0) * 1e9);
        } else if ((f->codec == kCodecRaw || f->codec == kCodecSegment) &&
                   payload.size() != f->raw_bytes) {
          throw MessageError(what + ": payload of " + std::to_string(payload.size()) +
                             " bytes, the sample says " + std::to_string(f->raw_bytes));
        } else if (f->codec == kCodecRaw) {
          words = WordPool::instance().take(f->raw_bytes / sizeof(capnp::word));
          std::memcpy(words.begin(), payload.data(), payload.size());
        } else if (f->codec == kCodecSegment) {
          // The segment table of a single segment in front, then the segment.
          const std::size_t n = f->raw_bytes / sizeof(capnp::word);
          words = WordPool::instance().take(n + 1);
          const std::uint32_t table[2] = {0, static_cast<std::uint32_t>(n)};
          std::memcpy(words.begin(), table, sizeof table);
          std::memcpy(words.begin() + 1, payload.data(), payload.size());
        } else {
          throw MessageError(what + ": unknown codec " + std::to_string(f->codec));
        }
        std::shared_ptr<const MessageStorage> message =
            decodeMessageWords(kj::mv(words), what, limits);
        import.counters->received += 1;
        // The receiving thread runs a free subscriber itself: one wake-up per message, not two.
        import.deliver(std::move(message), false, ImportDelivery::kRunHere);
      } catch (const MessageError& e) {
        import.counters->rejected += 1;
        if (!import.warned) {
          import.warned = true;
          std::fprintf(stderr, "warning: %s (dropped; later ones are only counted)\n", e.what());
        }
      }
    }
    dds_return_loan(import.reader, samples, n);
  }
}

std::string DdsTransport::configXml(const DdsOptions& o) {
  std::string xml = "<CycloneDDS><Domain id=\"any\"><General>";
  if (!o.interface.empty()) {
    const bool address = o.interface.find_first_of(".:") != std::string::npos;
    xml.append("<Interfaces><NetworkInterface ")
        .append(address ? "address" : "name")
        .append("=\"")
        .append(o.interface)
        .append("\"/></Interfaces>");
  }
  if (!o.peers.empty()) xml.append("<AllowMulticast>false</AllowMulticast>");
  // Large samples (submaps, maps, clouds) on loopback: bigger UDP messages and socket buffers.
  xml.append("<MaxMessageSize>65500B</MaxMessageSize></General><Discovery>");
  xml.append("<LeaseDuration>")
      .append(std::to_string(static_cast<long long>(o.lease_s * 1000)))
      .append("ms</LeaseDuration>");
  if (!o.peers.empty()) {
    xml.append("<ParticipantIndex>auto</ParticipantIndex>")
        .append("<MaxAutoParticipantIndex>60</MaxAutoParticipantIndex><Peers>");
    for (const auto& p : o.peers) xml.append("<Peer address=\"").append(p).append("\"/>");
    xml.append("</Peers>");
  }
  xml.append("</Discovery>");
  xml.append("<Internal><SocketReceiveBufferSize min=\"default\" max=\"8MB\"/>")
      .append("<SocketSendBufferSize min=\"default\" max=\"8MB\"/>")
      .append("<MaxSampleSize>")
      .append(std::to_string(o.max_message_bytes + 4096))
      .append("B</MaxSampleSize></Internal></Domain></CycloneDDS>");
  return xml;
}

void DdsTransport::validate(const DdsOptions& o) {
  if (o.domain > 230) {
    throw ConfigError("dds.domain: " + std::to_string(o.domain) +
                      " is out of range, expected 0-230");
  }
  if (o.partition.empty()) {
    throw ConfigError(
        "dds.partition: missing; name the deployment's partition so that it never joins another "
        "system's topics");
  }
  for (const auto& [topic, level] : o.compression) {
    if (level < 1 || level > 19) {
      throw ConfigError("dds.compression." + topic + ": level " + std::to_string(level) +
                        " is out of range, expected 1-19");
    }
  }
  if (o.max_message_bytes == 0 || o.max_message_bytes > (std::size_t{1} << 31)) {
    throw ConfigError("dds.max_message_bytes: expected 1 to 2^31");
  }
  if (o.reliable_depth == 0) throw ConfigError("dds.reliable_depth: expected at least 1");
  if (o.replay_depth > (1u << 20)) {
    throw ConfigError("dds.replay_depth: " + std::to_string(o.replay_depth) +
                      " is out of range, expected 0 to 1048576");
  }
  if (!(o.lease_s >= 0.5 && o.lease_s <= 3600)) {
    throw ConfigError("dds.lease_s: " + std::to_string(o.lease_s) +
                      " is out of range, expected 0.5 to 3600 seconds");
  }
  if (!(o.reconnect_timeout_s >= 0 && o.reconnect_timeout_s <= 86400)) {
    throw ConfigError("dds.reconnect_timeout_s: " + std::to_string(o.reconnect_timeout_s) +
                      " is out of range, expected 0 to 86400 seconds");
  }
}

DdsOptions loadDdsOptions(const Params& params) {
  DdsOptions o;
  params.rejectUnknown({"domain", "partition", "interface", "peers", "max_message_bytes",
                        "reliable_depth", "replay_depth", "lease_s", "reconnect_timeout_s",
                        "compression"});
  params.read("domain", o.domain);
  params.read("partition", o.partition);
  params.read("interface", o.interface);
  params.read("peers", o.peers);
  std::uint64_t max_bytes = o.max_message_bytes;
  params.read("max_message_bytes", max_bytes);
  o.max_message_bytes = static_cast<std::size_t>(max_bytes);
  params.read("reliable_depth", o.reliable_depth);
  params.read("replay_depth", o.replay_depth);
  params.read("lease_s", o.lease_s);
  params.read("reconnect_timeout_s", o.reconnect_timeout_s);
  if (const YAML::Node c = params.node()["compression"]) {
    if (!c.IsMap()) {
      throw ConfigError(params.locate("compression") + ": expected a mapping {topic: zstd level}");
    }
    const Params levels = params.child("compression");
    for (const auto& kv : c) {
      const std::string topic = kv.first.as<std::string>();
      int level = 0;
      levels.read(topic.c_str(), level);
      o.compression[topic] = level;
    }
  }
  try {
    DdsTransport::validate(o);
  } catch (const ConfigError& e) {
    throw ConfigError(params.where() + ": " + e.what());
  }
  return o;
}

DdsTransport::DdsTransport(DdsOptions options, std::string node_name)
    : impl_(std::make_unique<Impl>()) {
  validate(options);
  impl_->options = std::move(options);
  impl_->node = std::move(node_name);
  std::random_device rd;
  impl_->origin = (std::uint64_t{rd()} << 32) ^ rd();
  DomainRegistry::instance().acquire(impl_->options.domain, configXml(impl_->options));
  dds_qos_t* qos = dds_create_qos();
  dds_qset_entity_name(qos, ("tessera_" + impl_->node).c_str());
  impl_->participant = dds_create_participant(impl_->options.domain, qos, nullptr);
  dds_delete_qos(qos);
  if (impl_->participant < 0) {
    DomainRegistry::instance().release(impl_->options.domain);
    throw ConfigError("dds: cannot join domain " + std::to_string(impl_->options.domain) + ": " +
                      ddsError(impl_->participant));
  }
  dds_qos_t* pq = dds_create_qos();
  dds_qset_partition1(pq, impl_->options.partition.c_str());
  impl_->publisher = dds_create_publisher(impl_->participant, pq, nullptr);
  impl_->subscriber = dds_create_subscriber(impl_->participant, pq, nullptr);
  dds_delete_qos(pq);
  impl_->waitset = dds_create_waitset(impl_->participant);
}

DdsTransport::~DdsTransport() {
  stopReceiving();
  dds_delete(impl_->participant);
  DomainRegistry::instance().release(impl_->options.domain);
}

void DdsTransport::attach(Runtime& runtime, const std::vector<DdsTopic>& topics) {
  for (const auto& t : topics) {
    const dds_entity_t topic = impl_->topicEntity(t.name);
    const auto level_it = impl_->options.compression.find(t.name);
    dds_qos_t* qos = dds_create_qos();
    if (t.reliable) {
      dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
      dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
      const auto depth = static_cast<std::int32_t>(impl_->options.reliable_depth);
      dds_qset_resource_limits(qos, depth, DDS_LENGTH_UNLIMITED, depth);
      if (impl_->options.replay_depth > 0) {
        // The writer keeps its last samples for readers that join late or come back; readers
        // ask for them. Live readers still get every sample (KEEP_ALL above).
        const auto replay = static_cast<std::int32_t>(impl_->options.replay_depth);
        dds_qset_durability(qos, DDS_DURABILITY_TRANSIENT_LOCAL);
        dds_qset_durability_service(qos, 0, DDS_HISTORY_KEEP_LAST, replay, DDS_LENGTH_UNLIMITED,
                                    DDS_LENGTH_UNLIMITED, DDS_LENGTH_UNLIMITED);
      }
    } else {
      dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
      dds_qset_history(qos, DDS_HISTORY_KEEP_LAST,
                       static_cast<std::int32_t>(std::max(t.depth, 1u)));
    }
    if (t.exported) {
      auto e = std::make_shared<Impl::Export>();
      e->impl = impl_.get();
      e->topic = t;
      e->level = level_it == impl_->options.compression.end() ? 0 : level_it->second;
      e->counters = &impl_->countersFor(t.name);
      e->writer = dds_create_writer(impl_->publisher, topic, qos, nullptr);
      if (e->writer < 0) {
        dds_delete_qos(qos);
        throw ConfigError("dds: cannot create a writer for '" + t.name +
                          "': " + ddsError(e->writer));
      }
      e->local = runtime.importTopic(t.name, t.type);
      runtime.exportTopic(t.name, t.type, e);
      impl_->exports.push_back(e);
    }
    if (t.imported) {
      auto i = std::make_unique<Impl::Import>();
      i->topic = t;
      i->counters = &impl_->countersFor(t.name);
      dds_qset_ignorelocal(qos, DDS_IGNORELOCAL_PARTICIPANT);
      i->reader = dds_create_reader(impl_->subscriber, topic, qos, nullptr);
      if (i->reader < 0) {
        dds_delete_qos(qos);
        throw ConfigError("dds: cannot create a reader for '" + t.name +
                          "': " + ddsError(i->reader));
      }
      // An exported topic already has this host's import (local delivery) from above.
      i->deliver = t.exported ? impl_->exports.back()->local : runtime.importTopic(t.name, t.type);
      i->condition = dds_create_readcondition(i->reader, DDS_ANY_STATE);
      dds_waitset_attach(impl_->waitset, i->condition,
                         static_cast<dds_attach_t>(impl_->imports.size()));
      impl_->imports.push_back(std::move(i));
    }
    dds_delete_qos(qos);
  }
}

std::vector<std::string> DdsTransport::unconnected() const {
  std::vector<std::string> out;
  for (const auto& i : impl_->imports) {
    dds_subscription_matched_status_t s{};
    if (dds_get_subscription_matched_status(i->reader, &s) == DDS_RETCODE_OK &&
        s.current_count == 0)
      out.push_back("'" + i->topic.name + "' (no publisher)");
  }
  for (const auto& e : impl_->exports) {
    dds_publication_matched_status_t s{};
    if (dds_get_publication_matched_status(e->writer, &s) == DDS_RETCODE_OK && s.current_count == 0)
      out.push_back("'" + e->topic.name + "' (no subscriber)");
  }
  return out;
}

bool DdsTransport::upstreamLeft() {
  if (impl_->imports.empty()) return false;
  for (const auto& i : impl_->imports) {
    dds_subscription_matched_status_t s{};
    bool gone = dds_get_subscription_matched_status(i->reader, &s) == DDS_RETCODE_OK &&
                s.total_count > 0 && s.current_count == 0;
    if (!gone) {
      impl_->gone_since.reset();
      return false;
    }
  }
  const auto now = std::chrono::steady_clock::now();
  if (!impl_->gone_since) impl_->gone_since = now;
  {
    // Every sender ended its streams: they left on purpose.
    std::lock_guard lock(impl_->origins_mutex);
    if (std::includes(impl_->ended_origins.begin(), impl_->ended_origins.end(),
                      impl_->seen_origins.begin(), impl_->seen_origins.end()))
      return true;
  }
  // Some vanished (a lost link, a crash): wait for them to come back, for a while.
  return std::chrono::duration<double>(now - *impl_->gone_since).count() >=
         impl_->options.reconnect_timeout_s;
}

bool DdsTransport::drained() const {
  for (const auto& i : impl_->imports) {
    if (dds_triggered(i->condition) != 0) return false;
  }
  // After the readers: a sample taken between the two checks is seen as being handed over.
  return !impl_->taking.load();
}

std::vector<std::string> DdsTransport::flush(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::vector<std::string> unacknowledged;
  for (const auto& e : impl_->exports) e->end();
  for (const auto& e : impl_->exports) {
    if (!e->topic.reliable) continue;
    const auto left = std::chrono::duration_cast<std::chrono::nanoseconds>(
        deadline - std::chrono::steady_clock::now());
    if (dds_wait_for_acks(e->writer, std::max<dds_duration_t>(left.count(), 0)) != DDS_RETCODE_OK)
      unacknowledged.push_back(e->topic.name);
  }
  return unacknowledged;
}

bool DdsTransport::waitForPeers(std::chrono::milliseconds timeout,
                                const std::function<bool()>& give_up) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!unconnected().empty()) {
    if (std::chrono::steady_clock::now() >= deadline || (give_up && give_up())) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

void DdsTransport::startReceiving() {
  if (impl_->receiver.joinable() || impl_->imports.empty()) return;
  impl_->stopping = false;
  impl_->receiver = std::thread([impl = impl_.get()] {
    std::vector<dds_attach_t> fired(impl->imports.size() + 1);
    while (!impl->stopping.load()) {
      const dds_return_t n =
          dds_waitset_wait(impl->waitset, fired.data(), fired.size(), DDS_MSECS(100));
      if (n < 0) {
        std::fprintf(stderr, "warning: dds: wait failed: %s\n", ddsError(n).c_str());
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
        continue;
      }
      impl->taking = true;
      for (dds_return_t k = 0; k < n; ++k) {
        const auto index = static_cast<std::size_t>(fired[static_cast<std::size_t>(k)]);
        if (index < impl->imports.size()) impl->takeAll(*impl->imports[index]);
      }
      impl->taking = false;
    }
  });
}

void DdsTransport::stopReceiving() {
  if (!impl_->receiver.joinable()) return;
  impl_->stopping = true;
  dds_waitset_set_trigger(impl_->waitset, true);
  impl_->receiver.join();
  dds_waitset_set_trigger(impl_->waitset, false);
}

DdsStats DdsTransport::stats() const {
  DdsStats out;
  for (const auto& [name, c] : impl_->counters) {
    auto& s = out.topics[name];
    s.sent = c->sent;
    s.received = c->received;
    s.bytes_raw = c->bytes_raw;
    s.bytes_sent = c->bytes_sent;
    s.lost = c->lost;
    s.rejected = c->rejected;
    s.duplicates = c->duplicates;
    s.compress_s = static_cast<double>(c->compress_ns.load()) * 1e-9;
    s.decompress_s = static_cast<double>(c->decompress_ns.load()) * 1e-9;
  }
  return out;
}

}  // namespace tessera
