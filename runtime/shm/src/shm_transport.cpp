// The iceoryx transport (tessera/shm/shm_transport.hpp): publishers loan chunks and build
// messages in them, a receiving thread hands them to the runtime's mailboxes, and the chunk-extent
// bookkeeping zeroes only what a reused chunk needs. Longer than ~600 lines on purpose: the
// three share one ownership protocol over the chunks, which reads best in one place.
#include <tessera/messages/detail/storage_allocator.hpp>
#include <tessera/shm/shm_transport.hpp>

#include "runtime_impl.hpp"
#include "tsan_handoff.hpp"

#include <iceoryx_posh/mepoo/chunk_header.hpp>
#include <iceoryx_posh/popo/untyped_publisher.hpp>
#include <iceoryx_posh/popo/untyped_subscriber.hpp>
#include <iceoryx_posh/popo/user_trigger.hpp>
#include <iceoryx_posh/popo/wait_set.hpp>
#include <iceoryx_posh/runtime/posh_runtime.hpp>

#include <capnp/serialize.h>
#include <kj/debug.h>
#include <pthread.h>

#include <algorithm>
#include <cstring>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#include <mutex>
#include <thread>

namespace tessera {

namespace {

constexpr std::uint32_t kChunkMagic = 0x31525354;  // "TSR1"
constexpr std::size_t kPrefixBytes = 16;           // magic, origin, extent, check
constexpr std::size_t kWord = sizeof(capnp::word);
static_assert(kShmChunkOverhead == kPrefixBytes + kWord, "prefix + one-segment table");
// A loan with a blob: prefix and a two-segment table (message, then blob).
constexpr std::size_t kBlobChunkOverhead = kPrefixBytes + 2 * kWord;

std::size_t wholeWords(std::size_t bytes) {
  return (bytes + kWord - 1) / kWord;
}

struct Prefix {
  std::uint32_t magic;
  std::uint32_t origin;  // process index of the sender
  std::uint32_t extent;  // bytes from the payload start the chunk's last use may have written
  std::uint32_t check;   // extentCheck(extent): the extent is trusted only when it matches
};

std::uint32_t extentCheck(std::uint32_t extent) {
  return (extent ^ 0x5bd1e995u) * 0x9e3779b1u;
}

std::size_t capacityOf(const void* payload) {
  const auto* header = iox::mepoo::ChunkHeader::fromUserPayload(payload);
  const auto offset = static_cast<std::size_t>(static_cast<const std::byte*>(payload) -
                                               reinterpret_cast<const std::byte*>(header));
  return header->chunkSize() - offset;
}

iox::capro::ServiceDescription serviceOf(const std::string& topic) {
  // iceoryx ids hold at most 100 characters; topic names are far shorter in practice.
  if (topic.size() > iox::capro::IdString_t::capacity()) {
    throw ConfigError("topic '" + topic + "': name longer than " +
                      std::to_string(iox::capro::IdString_t::capacity()) +
                      " characters cannot cross processes");
  }
  return {"tessera", iox::capro::IdString_t(iox::cxx::TruncateToCapacity, topic.c_str()), "capnp"};
}

/// memset(p, 0, n), but a large span is written with streaming stores, past the caches: the
/// builder overwrites most of it at once, and a second full pass of dirty lines through the
/// caches evicts what the next wake-up needs (a 4 MiB message took ~5 us longer to deliver).
void zeroBytes(std::byte* p, std::size_t n) {
  constexpr std::size_t kStreamFrom = std::size_t{256} << 10;
#if defined(__SSE2__)
  if (n >= kStreamFrom) {
    const std::size_t head = (16 - reinterpret_cast<std::uintptr_t>(p) % 16) % 16;
    std::memset(p, 0, head);
    const __m128i zero = _mm_setzero_si128();
    auto* v = reinterpret_cast<__m128i*>(p + head);
    const std::size_t blocks = (n - head) / 16;
    for (std::size_t i = 0; i < blocks; ++i) _mm_stream_si128(v + i, zero);
    std::memset(p + head + blocks * 16, 0, n - head - blocks * 16);
    _mm_sfence();  // streaming stores are weakly ordered: done before the builder writes
    return;
  }
#endif
  std::memset(p, 0, n);
}

}  // namespace

namespace detail {

std::size_t chunkExtent(const std::byte* payload, std::size_t capacity) {
  Prefix p{};
  std::memcpy(&p, payload, sizeof p);
  if (p.magic == kChunkMagic && p.check == extentCheck(p.extent) && p.extent <= capacity)
    return p.extent;
  return capacity;
}

void recordChunkExtent(std::byte* payload, std::uint32_t origin, std::size_t extent) {
  const auto e = static_cast<std::uint32_t>(extent);
  const Prefix p{kChunkMagic, origin, e, extentCheck(e)};
  std::memcpy(payload, &p, sizeof p);
}

std::size_t zeroChunkForBuilder(std::byte* payload, std::size_t capacity, std::size_t end,
                                std::uint32_t origin, std::size_t written_end) {
  const std::size_t before = chunkExtent(payload, capacity);
  const std::size_t will_write = std::max(end, written_end);
  if (before > kPrefixBytes) {
    // A chunk of unknown history is zeroed throughout once; from then on only what each use
    // wrote is.
    const std::size_t zero_to = before == capacity ? capacity : std::min(before, end);
    zeroBytes(payload + kPrefixBytes, zero_to - kPrefixBytes);
    const std::size_t rest = zero_to < before ? before : 0;
    recordChunkExtent(payload, origin, std::max(will_write, rest));
    return rest;
  }
  recordChunkExtent(payload, origin, will_write);
  return 0;
}

std::uint64_t SendGaps::account(std::uint64_t publisher, std::uint64_t sequence) {
  auto it = std::find_if(next_.begin(), next_.end(),
                         [&](const auto& entry) { return entry.first == publisher; });
  if (it == next_.end()) {
    next_.emplace_back(publisher, join_anywhere_ ? sequence : 0);  // a port numbers from 0
    it = next_.end() - 1;
  }
  if (it != next_.begin()) std::iter_swap(it, next_.begin());
  auto& next = next_.front().second;
  // A number behind the expected one cannot come from a live port (iceoryx numbers each send
  // of a port once): count the message alone rather than a wrapped gap.
  const std::uint64_t missed = sequence >= next ? sequence - next : 0;
  next = sequence + 1;
  return missed + 1;
}

}  // namespace detail

// ------------------------------------------------------------------ exports

struct ShmExport;

struct ShmTransport::Impl {
  ShmTransportOptions options;
  std::vector<std::shared_ptr<ShmExport>> exports;
  struct Import;
  std::vector<std::shared_ptr<Import>> imports;
  std::atomic<std::uint64_t> copies{0}, drops{0}, heap_fallbacks{0}, sent{0}, received{0},
      unsent{0};
  std::atomic<bool> cut_off{false};  // cutOff(): nothing more leaves this process
  std::optional<iox::popo::UserTrigger> wake;
  std::thread receiver;
  // receiveHere()'s; reset when the receiving thread starts (a subscriber has one WaitSet).
  std::optional<iox::popo::WaitSet<>> caller_waitset;
  std::atomic<bool> quit{false};
  // The receiving thread may run handlers itself unless a handler it runs could publish into a
  // full queue that only this same thread empties (a topic this process sends and receives).
  bool run_handlers_here = true;
};

/// A message being built in (the first segment of) a loaned chunk. Further segments, if the
/// message outgrows the chunk, come from the heap and are copied into a new chunk on send.
class ChunkLoan final : public detail::LoanStorage {
 public:
  /// The message is built in `segment_words` after the segment table; `blob_bytes` (0: none)
  /// follow it, not zeroed.
  ChunkLoan(std::shared_ptr<ShmExport> owner, void* payload, std::size_t segment_words,
            std::size_t blob_bytes);
  ~ChunkLoan() noexcept override;
  capnp::MessageBuilder& builder() override { return *builder_; }
  void seal() override { segments_ = builder_->getSegmentsForOutput(); }
  capnp::AnyPointer::Reader root() const override {
    return const_cast<Builder&>(*builder_).getRoot<capnp::AnyPointer>().asReader();
  }
  kj::ArrayPtr<const kj::ArrayPtr<const capnp::word>> segments() const override {
    return segments_;
  }

  /// Writes prefix and segment table; true when the message sits wholly in the chunk.
  bool finishInPlace(std::uint32_t origin);
  void* payload() const { return payload_; }
  void disown() { payload_ = nullptr; }

 private:
  class Builder final : public capnp::MessageBuilder {
   public:
    explicit Builder(kj::ArrayPtr<capnp::word> first) : first_(first) {}
    kj::ArrayPtr<capnp::word> allocateSegment(capnp::uint minimum_size) override {
      if (!first_used_ && minimum_size <= first_.size()) {
        first_used_ = true;
        return first_;
      }
      first_used_ = true;
      overflow_ = true;
      const std::size_t words = std::max<std::size_t>(minimum_size, 1024);
      extra_.push_back(kj::heapArray<capnp::word>(words));
      std::memset(extra_.back().begin(), 0, words * kWord);
      return extra_.back().asPtr();
    }
    bool overflowed() const { return overflow_; }

   private:
    kj::ArrayPtr<capnp::word> first_;
    bool first_used_ = false, overflow_ = false;
    std::vector<kj::Array<capnp::word>> extra_;
  };

  std::shared_ptr<ShmExport> owner_;
  void* payload_;
  std::size_t segment_words_;
  std::size_t rest_ = 0;  // extent of an earlier use past what this builder may touch
  std::optional<Builder> builder_;
  kj::ArrayPtr<const kj::ArrayPtr<const capnp::word>> segments_;
};

struct ShmExport final : TopicExport, std::enable_shared_from_this<ShmExport> {
  ShmExport(const ShmTopic& t, const ShmTransportOptions& o, ShmTransport::Impl& transport)
      : topic(t), options(o), owner(transport) {
    iox::popo::PublisherOptions po;
    po.subscriberTooSlowPolicy = t.any_reliable
                                     ? iox::popo::ConsumerTooSlowPolicy::WAIT_FOR_CONSUMER
                                     : iox::popo::ConsumerTooSlowPolicy::DISCARD_OLDEST_DATA;
    publisher.emplace(serviceOf(t.name), po);
    if (o.routes.outgoing) routes = o.routes.outgoing(t.name, o.process_index);
  }

  std::shared_ptr<detail::LoanStorage> loan(std::size_t size_hint_bytes,
                                            std::size_t blob_bytes) override;
  bool send(const std::shared_ptr<const MessageStorage>& message) override;
  bool loopsBack() const override { return topic.loopback(); }

  /// Loans a chunk of `payload_bytes`; nullptr when every chunk of this publisher is in use
  /// or the pool is empty (the caller decides whether to wait).
  void* tryLoan(std::size_t payload_bytes, bool& exhausted);
  void checkFits(std::size_t payload_bytes) const {
    if (payload_bytes > options.max_chunk_bytes) {
      throw MessageError("topic '" + topic.name + "': a message of " +
                         std::to_string(payload_bytes - kShmChunkOverhead) +
                         " bytes does not fit the largest shared-memory chunk (" +
                         std::to_string(options.max_chunk_bytes - kShmChunkOverhead) +
                         " bytes, sized from the message family's bound); it cannot cross "
                         "processes");
    }
  }
  void publishChunk(void* payload) {
    detail::chunkHandedOff(payload);
    {
      std::lock_guard lock(mutex);
      publisher->publish(payload);
    }
    ++owner.sent;
    if (options.sent != nullptr) options.sent->fetch_add(topic.importing_processes);
    for (RouteCounters* r : routes) r->sent.fetch_add(1);
  }
  void release(void* payload) {
    detail::chunkHandedOff(payload);
    std::lock_guard lock(mutex);
    publisher->release(payload);
  }

  ShmTopic topic;
  ShmTransportOptions options;
  ShmTransport::Impl& owner;
  std::mutex mutex;  // iceoryx ports are not thread-safe; actors may share a topic
  std::optional<iox::popo::UntypedPublisher> publisher;
  std::vector<RouteCounters*> routes;  // the ledger's routes from here (may be empty)
};

ChunkLoan::ChunkLoan(std::shared_ptr<ShmExport> owner, void* payload, std::size_t segment_words,
                     std::size_t blob_bytes)
    : owner_(std::move(owner)), payload_(payload), segment_words_(segment_words) {
  auto* bytes = static_cast<std::byte*>(payload);
  const std::size_t start = blob_bytes > 0 ? kBlobChunkOverhead : kShmChunkOverhead;
  const std::size_t end = start + segment_words * kWord;
  // Chunks are reused: of what the builder may hand out, zero only what an earlier use wrote.
  // The blob is the producer's to overwrite, so it is only counted as written.
  rest_ =
      detail::zeroChunkForBuilder(bytes, capacityOf(payload), end, owner_->options.process_index,
                                  end + wholeWords(blob_bytes) * kWord);
  if (blob_bytes > 0) {
    blob_ = {bytes + end, blob_bytes};
    // Readers see the last word whole: its padding is zero, not an earlier message's bytes.
    std::memset(bytes + end + (wholeWords(blob_bytes) - 1) * kWord, 0, kWord);
  }
  builder_.emplace(kj::arrayPtr(reinterpret_cast<capnp::word*>(bytes + start), segment_words));
}

ChunkLoan::~ChunkLoan() noexcept {
  try {
    builder_.reset();
  } catch (...) {
  }
  if (payload_ != nullptr) owner_->release(payload_);  // built but never sent
}

bool ChunkLoan::finishInPlace(std::uint32_t origin) {
  auto* bytes = static_cast<std::byte*>(payload_);
  // Not in place: the chunk goes back unsent, and the extent recorded at the loan stays.
  if (builder_->overflowed()) return false;
  if (blob_.empty()) {
    if (segments_.size() != 1) return false;
    const std::uint32_t table[2] = {0, static_cast<std::uint32_t>(segments_[0].size())};
    std::memcpy(bytes + kPrefixBytes, table, sizeof(table));
    detail::recordChunkExtent(bytes, origin,
                              std::max(kShmChunkOverhead + segments_[0].size() * kWord, rest_));
    return true;
  }
  // Segment 1 is the blob, where it lies: right after the whole first segment, whose unused
  // tail was zeroed at the loan. A blob never attached is an unreferenced segment.
  const std::size_t blob_words = wholeWords(blob_.size());
  const auto* blob_start = reinterpret_cast<const capnp::word*>(blob_.data());
  const bool attached = segments_.size() == 2 && segments_[1].begin() == blob_start &&
                        segments_[1].size() == blob_words;
  if (!(segments_.size() == 1 || attached)) return false;
  const std::uint32_t table[4] = {1, static_cast<std::uint32_t>(segment_words_),
                                  static_cast<std::uint32_t>(blob_words), 0};
  std::memcpy(bytes + kPrefixBytes, table, sizeof(table));
  const auto blob_end = static_cast<std::size_t>(blob_.data() - bytes) + blob_words * kWord;
  detail::recordChunkExtent(bytes, origin, std::max(blob_end, rest_));
  return true;
}

void* ShmExport::tryLoan(std::size_t payload_bytes, bool& exhausted) {
  exhausted = false;
  std::lock_guard lock(mutex);
  auto r = publisher->loan(static_cast<std::uint32_t>(payload_bytes), alignof(capnp::word));
  if (!r.has_error()) {
    detail::chunkTakenOver(r.value());
    return r.value();
  }
  exhausted = r.get_error() == iox::popo::AllocationError::RUNNING_OUT_OF_CHUNKS;
  return nullptr;
}

std::shared_ptr<detail::LoanStorage> ShmExport::loan(std::size_t size_hint_bytes,
                                                     std::size_t blob_bytes) {
  // Headroom over the hint: the root struct, header, list tags and padding.
  std::size_t words = (std::max(size_hint_bytes, kShmDefaultMessageBytes) + 511) / kWord + 64;
  const std::size_t overhead = blob_bytes > 0 ? kBlobChunkOverhead : kShmChunkOverhead;
  const std::size_t blob_space = wholeWords(blob_bytes) * kWord;
  std::size_t bytes = overhead + words * kWord + blob_space;
  if (bytes > options.max_chunk_bytes) {
    checkFits(overhead + size_hint_bytes + blob_space);  // the message itself can never fit
    bytes = options.max_chunk_bytes;
    words = (bytes - overhead - blob_space) / kWord;
  }
  bool exhausted = false;
  if (void* payload = tryLoan(bytes, exhausted)) {
    return std::make_shared<ChunkLoan>(shared_from_this(), payload, words, blob_bytes);
  }
  // All of this publisher's loans are out (an actor holds many unsent messages) or the pool is
  // empty: build on the heap; send() copies into a chunk when one is free.
  ++owner.heap_fallbacks;
  return detail::makeBuilderStorage(size_hint_bytes, blob_bytes);
}

bool ShmExport::send(const std::shared_ptr<const MessageStorage>& message) {
  if (owner.cut_off.load()) {
    ++owner.unsent;  // the message keeps its storage (a loaned chunk too) for local delivery
    return false;
  }
  if (auto* chunk = dynamic_cast<const ChunkLoan*>(message.get())) {
    auto* mine = const_cast<ChunkLoan*>(chunk);
    if (mine->finishInPlace(options.process_index)) {
      void* payload = mine->payload();
      mine->disown();
      publishChunk(payload);
      return true;
    }
  }
  // Copy once into a chunk of the exact size (standard framing after the prefix).
  auto segments = message->segments();
  const std::size_t table_words = (segments.size() + 2) / 2;
  std::size_t bytes = kPrefixBytes + table_words * kWord;
  for (auto s : segments) bytes += s.size() * kWord;
  checkFits(bytes - kPrefixBytes + kWord);
  void* payload = nullptr;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  for (int attempt = 0;; ++attempt) {
    bool exhausted = false;
    payload = tryLoan(bytes, exhausted);
    if (payload != nullptr) break;
    if (std::chrono::steady_clock::now() > deadline) {
      throw MessageError("topic '" + topic.name + "': no shared-memory chunk of " +
                         std::to_string(bytes) +
                         " bytes became free within 10 s (subscribers hold them all)");
    }
    std::this_thread::sleep_for(std::chrono::microseconds(attempt < 100 ? 10 : 1000));
  }
  auto* out = static_cast<std::byte*>(payload);
  // Written without zeroing: whatever an earlier use left past `bytes` stays recorded.
  detail::recordChunkExtent(out, options.process_index,
                            std::max(bytes, detail::chunkExtent(out, capacityOf(payload))));
  std::vector<std::uint32_t> table(table_words * 2, 0);
  table[0] = static_cast<std::uint32_t>(segments.size() - 1);
  for (std::size_t i = 0; i < segments.size(); ++i) {
    table[i + 1] = static_cast<std::uint32_t>(segments[i].size());
  }
  std::memcpy(out + kPrefixBytes, table.data(), table_words * kWord);
  std::size_t at = kPrefixBytes + table_words * kWord;
  for (auto s : segments) {
    std::memcpy(out + at, s.begin(), s.size() * kWord);
    at += s.size() * kWord;
  }
  ++owner.copies;
  publishChunk(payload);
  return true;
}

// ------------------------------------------------------------------ imports

struct ShmTransport::Impl::Import {
  ShmTopic topic;
  ImportFn deliver;
  std::mutex mutex;  // take and release from different threads
  std::optional<iox::popo::UntypedSubscriber> subscriber;
  detail::SendGaps gaps;  // receiving thread only
  /// Gives a taken chunk back to iceoryx, from whichever thread read it last.
  void release(const void* payload) {
    detail::chunkHandedOff(payload);
    std::lock_guard lock(mutex);
    subscriber->release(payload);
  }
  // The delivery ledger's view (receiving thread only): each sending process's route, resolved
  // at its first message, and the gaps in each publisher port's numbering from where this
  // process joined it.
  std::vector<std::pair<std::uint32_t, RouteCounters*>> routes;
  detail::SendGaps route_gaps{true};
  RouteCounters* routeFrom(const ShmTransportOptions& o, std::uint32_t origin) {
    for (const auto& [from, r] : routes) {
      if (from == origin) return r;
    }
    RouteCounters* r =
        o.routes.incoming ? o.routes.incoming(topic.name, origin, o.process_index) : nullptr;
    routes.emplace_back(origin, r);
    return r;
  }
};

namespace {

/// A received chunk, read in place. Releases the chunk when the last reader is done.
class ChunkView final : public MessageStorage {
 public:
  ChunkView(std::shared_ptr<ShmTransport::Impl::Import> import, const void* payload,
            kj::ArrayPtr<const capnp::word> words)
      : import_(std::move(import)), payload_(payload) {
    capnp::ReaderOptions options;
    // One reader serves every local subscriber: give it room for many full traversals.
    options.traversalLimitInWords = std::max<std::uint64_t>(64 * words.size(), 1u << 20);
    // The segment table is read here rather than by a FlatArrayMessageReader, which allocates
    // for every segment past the first (a blob message has two).
    KJ_REQUIRE(words.size() >= 1, "chunk too small for a segment table");
    std::uint32_t count_minus_one = 0;
    std::memcpy(&count_minus_one, words.begin(), sizeof(count_minus_one));
    KJ_REQUIRE(count_minus_one < kMaxSegments, "too many segments", count_minus_one);
    const std::size_t count = std::size_t{count_minus_one} + 1;
    const std::size_t table_words = count / 2 + 1;
    KJ_REQUIRE(table_words <= words.size(), "segment table past the chunk's end");
    kj::ArrayPtr<const capnp::word>* segments = first_;
    if (count > 2) {
      more_ = kj::heapArray<kj::ArrayPtr<const capnp::word>>(count);
      segments = more_.begin();
    }
    std::size_t at = table_words;
    for (std::size_t i = 0; i < count; ++i) {
      std::uint32_t size = 0;
      std::memcpy(&size, reinterpret_cast<const std::byte*>(words.begin()) + 4 * (i + 1),
                  sizeof(size));
      KJ_REQUIRE(size <= words.size() - at, "segment past the chunk's end", i, size);
      segments[i] = kj::arrayPtr(words.begin() + at, size);
      at += size;
    }
    segments_ = kj::arrayPtr(segments, count);
    reader_.emplace(segments_, options);
  }
  ~ChunkView() noexcept override {
    try {
      reader_.reset();
    } catch (...) {
    }
    import_->release(payload_);
  }
  capnp::AnyPointer::Reader root() const override {
    return const_cast<capnp::SegmentArrayMessageReader&>(*reader_).getRoot<capnp::AnyPointer>();
  }
  kj::ArrayPtr<const kj::ArrayPtr<const capnp::word>> segments() const override {
    return segments_;
  }

 private:
  std::shared_ptr<ShmTransport::Impl::Import> import_;
  const void* payload_;
  static constexpr std::uint32_t kMaxSegments = 512;  // as Cap'n Proto's own reader
  std::optional<capnp::SegmentArrayMessageReader> reader_;
  kj::ArrayPtr<const capnp::word> first_[2];
  kj::Array<kj::ArrayPtr<const capnp::word>> more_;
  kj::ArrayPtr<const kj::ArrayPtr<const capnp::word>> segments_;
};

}  // namespace

ShmTransport::ShmTransport(ShmTransportOptions options) : impl_(std::make_unique<Impl>()) {
  impl_->options = std::move(options);
  if (impl_->options.runtime_name.empty() ||
      impl_->options.runtime_name.size() > iox::RuntimeName_t::capacity()) {
    throw ConfigError("shared-memory runtime name must have 1 to " +
                      std::to_string(iox::RuntimeName_t::capacity()) + " characters");
  }
  iox::runtime::PoshRuntime::initRuntime(
      iox::RuntimeName_t(iox::cxx::TruncateToCapacity, impl_->options.runtime_name.c_str()));
}

ShmTransport::~ShmTransport() {
  stopReceiving();
}

void ShmTransport::attach(Runtime& runtime, const std::vector<ShmTopic>& topics) {
  for (const auto& t : topics) {
    if (t.imported) {
      auto import = std::make_shared<Impl::Import>();
      import->topic = t;
      iox::popo::SubscriberOptions so;
      // A topic this process also sends must not lose its own messages in the shared queue: the
      // runtime counts them as pending until they are back. Local mailboxes still apply the
      // subscription's own policy (and count its drops).
      const bool reliable = t.import_policy.kind == MailboxPolicy::Kind::kReliable || t.loopback();
      so.queueCapacity = std::clamp<std::uint64_t>(
          std::max<std::uint64_t>(t.import_policy.capacity, reliable ? 16 : 1), 1,
          iox::MAX_SUBSCRIBER_QUEUE_CAPACITY);
      so.queueFullPolicy = reliable ? iox::popo::QueueFullPolicy::BLOCK_PRODUCER
                                    : iox::popo::QueueFullPolicy::DISCARD_OLDEST_DATA;
      import->subscriber.emplace(serviceOf(t.name), so);
      import->deliver = runtime.importTopic(t.name, t.type);
      impl_->imports.push_back(std::move(import));
    }
    if (t.loopback()) impl_->run_handlers_here = false;
    if (t.exported) {
      auto e = std::make_shared<ShmExport>(t, impl_->options, *impl_);
      impl_->exports.push_back(e);
      runtime.exportTopic(t.name, t.type, e);
    }
  }
}

std::vector<std::string> ShmTransport::unconnected() const {
  std::vector<std::string> out;
  for (auto& i : impl_->imports) {
    if (i->topic.publishing_processes == 0) continue;
    std::lock_guard lock(i->mutex);
    if (i->subscriber->getSubscriptionState() != iox::SubscribeState::SUBSCRIBED)
      out.push_back("'" + i->topic.name + "' (no publisher)");
  }
  for (auto& e : impl_->exports) {
    if (e->topic.importing_processes == 0) continue;
    std::lock_guard lock(e->mutex);
    if (!e->publisher->hasSubscribers()) out.push_back("'" + e->topic.name + "' (no subscriber)");
  }
  return out;
}

bool ShmTransport::waitForPublishers(std::chrono::milliseconds timeout,
                                     const std::function<bool()>& give_up) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    if (unconnected().empty()) return true;
    if (std::chrono::steady_clock::now() > deadline || (give_up && give_up())) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

namespace {
/// In-flight accounting of `n` messages received (or known lost on the way); wakes the
/// process even for n = 0 (a message nobody counted).
void countReceived(ShmTransport::Impl* impl, std::uint64_t n) {
  if (impl->options.received != nullptr && n > 0) impl->options.received->fetch_add(n);
  if (impl->options.arrived) impl->options.arrived();
}

/// Takes every chunk waiting on the imports and delivers it (see startReceiving()); returns
/// how many it took.
std::size_t deliverArrived(ShmTransport::Impl* impl) {
  std::size_t taken = 0;
  for (auto& i : impl->imports) {
    int deferred = 0;  // queued without running, in this batch
    for (;;) {
      const void* payload = nullptr;
      bool more = false;
      {
        std::lock_guard lock(i->mutex);
        auto r = i->subscriber->take();
        more = !r.has_error() && i->subscriber->hasData();
        if (r.has_error()) {
          if (r.get_error() == iox::popo::ChunkReceiveResult::TOO_MANY_CHUNKS_HELD_IN_PARALLEL) {
            // Local readers hold 256 chunks of this topic: let them finish first.
            std::this_thread::sleep_for(std::chrono::microseconds(200));
          }
          break;
        }
        payload = r.value();
      }
      detail::chunkTakenOver(payload);
      ++taken;
      const auto* header = iox::mepoo::ChunkHeader::fromUserPayload(payload);
      const std::size_t size = header->userPayloadSize();
      Prefix prefix{};
      if (size >= kShmChunkOverhead) std::memcpy(&prefix, payload, sizeof(prefix));
      // A program outside the deployment counts nothing as sent: nor is it counted here.
      const bool counted = !(prefix.magic == kChunkMagic && prefix.origin == kExternalProcess);
      // The sender counted every message once per importing process, including those a
      // full keep_latest queue here discarded before this thread could take them (the
      // newest always arrives): account for those too, or the deployment's clock would
      // wait for them for ever.
      const std::uint64_t accounted =
          counted ? i->gaps.account(static_cast<std::uint64_t>(header->originId()),
                                    header->sequenceNumber())
                  : 1;
      if (accounted > 1) {
        impl->drops += accounted - 1;
        countReceived(impl, accounted - 1);
      }
      if (size < kShmChunkOverhead || prefix.magic != kChunkMagic) {
        std::fprintf(stderr, "warning: topic '%s': dropped a chunk that is not a Tessera message\n",
                     i->topic.name.c_str());
        i->release(payload);
        continue;
      }
      const auto* words = reinterpret_cast<const capnp::word*>(
          static_cast<const std::byte*>(payload) + kPrefixBytes);
      std::shared_ptr<const MessageStorage> view;
      try {
        // Views are freed on whichever thread drops the last reader: a scalable allocator
        // keeps that cross-thread free off a shared malloc arena lock.
        view = std::allocate_shared<ChunkView>(detail::StorageAllocator<ChunkView>(), i, payload,
                                               kj::arrayPtr(words, (size - kPrefixBytes) / kWord));
      } catch (const kj::Exception& e) {
        // The view was not built, so its destructor will not release the chunk.
        std::fprintf(stderr, "warning: topic '%s': dropped a malformed message: %s\n",
                     i->topic.name.c_str(), e.getDescription().cStr());
        i->release(payload);
        // Handled (dropped): the sender counted it, so must the in-flight accounting.
        countReceived(impl, counted ? 1 : 0);
        continue;
      }
      if (counted) {
        if (RouteCounters* r = i->routeFrom(impl->options, prefix.origin)) {
          const std::uint64_t missed = i->route_gaps.account(
              static_cast<std::uint64_t>(header->originId()), header->sequenceNumber());
          if (missed > 1) r->gaps.fetch_add(missed - 1);
          r->received.fetch_add(1);
        }
      }
      const bool loopback = prefix.origin == impl->options.process_index && i->topic.loopback();
      // A burst is queued whole and run once: one pass over the strands per batch.
      auto delivery = ImportDelivery::kSchedule;
      if (impl->run_handlers_here) {
        delivery = more && deferred < 32 ? ImportDelivery::kDefer : ImportDelivery::kRunHere;
      }
      deferred = delivery == ImportDelivery::kDefer ? deferred + 1 : 0;
      i->deliver(std::move(view), loopback, delivery);
      ++impl->received;
      countReceived(impl, counted ? 1 : 0);  // 0: not counted, but still wakes the process
    }
    if (deferred > 0) i->deliver(nullptr, false, ImportDelivery::kRunHere);
  }
  return taken;
}

void watchImports(ShmTransport::Impl* impl, iox::popo::WaitSet<>& waitset) {
  for (auto& i : impl->imports) {
    waitset.attachState(*i->subscriber, iox::popo::SubscriberState::HAS_DATA).or_else([&](auto) {
      std::fprintf(stderr, "error: cannot watch topic '%s' for data\n", i->topic.name.c_str());
    });
  }
}
}  // namespace

void ShmTransport::startReceiving() {
  if (impl_->receiver.joinable() || impl_->imports.empty()) return;
  impl_->caller_waitset.reset();  // a subscriber is watched by one WaitSet at a time
  impl_->quit = false;
  impl_->wake.emplace();
  impl_->receiver = std::thread([impl = impl_.get()] {
    pthread_setname_np(pthread_self(), "tessera-shm-rx");
    iox::popo::WaitSet<> waitset;
    watchImports(impl, waitset);
    waitset.attachEvent(*impl->wake).or_else([](auto) {});
    while (!impl->quit.load()) {
      auto notes = waitset.wait();
      deliverArrived(impl);
    }
  });
}

void ShmTransport::receiveHere(std::chrono::microseconds timeout) {
  if (impl_->receiver.joinable()) {
    throw std::logic_error("ShmTransport: receiveHere() while the receiving thread runs");
  }
  if (impl_->imports.empty()) return;
  if (!impl_->caller_waitset) {
    impl_->caller_waitset.emplace();
    watchImports(impl_.get(), *impl_->caller_waitset);
  }
  // What already arrived is taken without waiting: an answer often comes while the caller is
  // still sending (the woken peer runs first on this CPU), and the WaitSet costs ~0.6 us even
  // when it need not sleep. The notification left pending makes the next wait return early,
  // off the path of an answer.
  if (deliverArrived(impl_.get()) > 0) return;
  auto notes = impl_->caller_waitset->timedWait(
      iox::units::Duration::fromMicroseconds(static_cast<std::uint64_t>(timeout.count())));
  deliverArrived(impl_.get());
}

void ShmTransport::stopReceiving() {
  if (!impl_->receiver.joinable()) return;
  impl_->quit = true;
  impl_->wake->trigger();
  impl_->receiver.join();
}

ShmStats ShmTransport::stats() const {
  ShmStats s;
  s.copies = impl_->copies.load();
  s.drops = impl_->drops.load();
  s.heap_fallbacks = impl_->heap_fallbacks.load();
  s.received = impl_->received.load();
  s.sent = impl_->sent.load();
  s.unsent = impl_->unsent.load();
  return s;
}

void ShmTransport::cutOff() {
  impl_->cut_off = true;
}

}  // namespace tessera
