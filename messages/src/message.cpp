#include <tessera/messages/detail/storage_allocator.hpp>
#include <tessera/messages/message.hpp>

#include <capnp/dynamic.h>
#include <kj/exception.h>

#include <array>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <sstream>
#include <vector>

namespace tessera {

std::size_t MessageStorage::sizeInBytes() const {
  std::size_t n = 0;
  for (auto s : segments()) n += s.size() * sizeof(capnp::word);
  return n;
}

const void* MessageStorage::address() const {
  auto segs = segments();
  return segs.size() == 0 ? nullptr : static_cast<const void*>(segs[0].begin());
}

namespace detail {
namespace {

/// Zeroed first segments by power-of-two size class. Buffers are calloc'ed once and recycled;
/// each class keeps a few, so memory held is bounded by kPerClass times the sizes in use.
class SegmentPool {
 public:
  static constexpr std::size_t kMinWords = std::size_t{1} << 10;  // 8 KiB: below, malloc is fine
  static constexpr std::size_t kMaxWords = std::size_t{1} << 24;  // 128 MiB: above, not pooled
  static constexpr std::size_t kPerClass = 16;

  static SegmentPool& instance() {
    static SegmentPool* pool = new SegmentPool;  // never destroyed: storages may outlive statics
    return *pool;
  }

  /// Rounds `words` up to its class. Returns nullptr when the size is not pooled.
  capnp::word* take(std::size_t& words) {
    if (words < kMinWords || words > kMaxWords) return nullptr;
    const unsigned cls = classOf(words);
    words = std::size_t{1} << cls;
    {
      std::lock_guard lock(mutex_);
      auto& free = free_[cls];
      if (!free.empty()) {
        capnp::word* p = free.back();
        free.pop_back();
        return p;
      }
    }
    return static_cast<capnp::word*>(std::calloc(words, sizeof(capnp::word)));
  }

  /// `p` must be zeroed again (Cap'n Proto's builder does this for the part it used).
  void give(capnp::word* p, std::size_t words) {
    const unsigned cls = classOf(words);
    {
      std::lock_guard lock(mutex_);
      auto& free = free_[cls];
      if (free.size() < kPerClass) {
        free.push_back(p);
        return;
      }
    }
    std::free(p);
  }

 private:
  static unsigned classOf(std::size_t words) {
    unsigned c = 0;
    while ((std::size_t{1} << c) < words) ++c;
    return c;
  }
  std::mutex mutex_;
  std::array<std::vector<capnp::word*>, 25> free_;
};

}  // namespace

std::shared_ptr<BuilderStorage> makeBuilderStorage(std::size_t size_hint_bytes,
                                                   std::size_t blob_bytes) {
  return std::allocate_shared<BuilderStorage>(StorageAllocator<BuilderStorage>(), size_hint_bytes,
                                              blob_bytes);
}

BuilderStorage::BuilderStorage(std::size_t size_hint_bytes, std::size_t blob_bytes) {
  if (blob_bytes > 0) {
    // Uninitialised (new T[], not make_unique): the producer overwrites it. Whole words, and
    // the padding of the last one zeroed, since the message shows it.
    const std::size_t words = (blob_bytes + sizeof(capnp::word) - 1) / sizeof(capnp::word);
    blob_words_.reset(new capnp::word[words]);
    std::memset(static_cast<void*>(blob_words_.get() + words - 1), 0, sizeof(capnp::word));
    blob_ = {reinterpret_cast<std::byte*>(blob_words_.get()), blob_bytes};
  }
  std::size_t hint_words = (size_hint_bytes + sizeof(capnp::word) - 1) / sizeof(capnp::word) + 16;
  if (hint_words <= kInlineWords) {
    std::memset(static_cast<void*>(inline_), 0, sizeof(inline_));
    builder_.emplace(kj::arrayPtr(inline_, kInlineWords));
  } else if ((pooled_ = SegmentPool::instance().take(hint_words)) != nullptr) {
    pooled_words_ = hint_words;
    builder_.emplace(kj::arrayPtr(pooled_, pooled_words_));
  } else {
    builder_.emplace(static_cast<unsigned>(hint_words));
  }
}

capnp::AnyPointer::Reader BuilderStorage::root() const {
  // getRoot is non-const in Cap'n Proto; on a sealed message it only reads.
  return const_cast<capnp::MallocMessageBuilder&>(*builder_)
      .getRoot<capnp::AnyPointer>()
      .asReader();
}

BuilderStorage::~BuilderStorage() noexcept {
  try {
    builder_.reset();  // zeroes the part of a caller-provided first segment it used
  } catch (...) {
    // Cannot happen for a well-formed builder; never return a possibly dirty buffer.
    pooled_ = nullptr;
  }
  if (pooled_ != nullptr) SegmentPool::instance().give(pooled_, pooled_words_);
}

void BuilderStorage::seal() {
  segments_ = builder_->getSegmentsForOutput();
}

kj::ArrayPtr<const kj::ArrayPtr<const capnp::word>> BuilderStorage::segments() const {
  return segments_;
}

namespace {
/// Storage for bytes that came from outside: an aligned copy plus a checked reader.
class FlatStorage final : public MessageStorage {
 public:
  FlatStorage(kj::Array<capnp::word> words, const capnp::ReaderOptions& options)
      : words_(kj::mv(words)),
        reader_(std::make_unique<capnp::FlatArrayMessageReader>(words_.asPtr(), options)) {
    // The segment table's first 32 bits hold the segment count minus one; the reader has
    // already checked the table against the buffer size.
    std::uint32_t count_minus_one = 0;
    std::memcpy(&count_minus_one, words_.begin(), sizeof(count_minus_one));
    segments_ = kj::heapArray<kj::ArrayPtr<const capnp::word>>(count_minus_one + 1);
    for (unsigned i = 0; i < segments_.size(); ++i) segments_[i] = reader_->getSegment(i);
  }
  capnp::AnyPointer::Reader root() const override { return reader_->getRoot<capnp::AnyPointer>(); }
  kj::ArrayPtr<const kj::ArrayPtr<const capnp::word>> segments() const override {
    return segments_.asPtr();
  }

 private:
  kj::Array<capnp::word> words_;
  // Held by pointer: the reader's destructor is noexcept(false), MessageStorage's is not.
  std::unique_ptr<capnp::FlatArrayMessageReader> reader_;
  kj::Array<kj::ArrayPtr<const capnp::word>> segments_;
};
}  // namespace
}  // namespace detail

namespace {
[[noreturn]] void throwAsMessageError(const std::string& what, const std::exception& e) {
  throw MessageError(what + ": malformed message: " + e.what());
}
}  // namespace

namespace {
std::string kjText(const kj::Exception& e) {
  return std::string(e.getDescription().cStr());
}
}  // namespace

namespace {
// Reads every field once through the schema, so element-size and pointer-kind mismatches are
// found here instead of in a subscriber. Primitive lists are checked by getting them, not
// element by element.
void visitStruct(capnp::DynamicStruct::Reader s, int depth);
void visitValue(const capnp::DynamicValue::Reader& v, int depth) {
  if (depth > 64) throw MessageError("nesting deeper than 64");
  switch (v.getType()) {
    case capnp::DynamicValue::STRUCT:
      visitStruct(v.as<capnp::DynamicStruct>(), depth + 1);
      break;
    case capnp::DynamicValue::LIST: {
      auto list = v.as<capnp::DynamicList>();
      const auto which = list.getSchema().whichElementType();
      if (which == capnp::schema::Type::STRUCT || which == capnp::schema::Type::LIST) {
        for (auto e : list) visitValue(e, depth + 1);
      }
      break;
    }
    default:
      break;
  }
}
void visitStruct(capnp::DynamicStruct::Reader s, int depth) {
  for (auto field : s.getSchema().getNonUnionFields()) {
    if (s.has(field)) visitValue(s.get(field), depth);
  }
  KJ_IF_MAYBE (field, s.which()) {
    if (s.has(*field)) visitValue(s.get(*field), depth);
  }
}
}  // namespace

void validateTyped(const MessageStorage& storage, capnp::StructSchema schema,
                   const std::string& what) {
  try {
    visitStruct(storage.root().getAs<capnp::DynamicStruct>(schema), 0);
  } catch (const kj::Exception& e) {
    throw MessageError(what + ": not a valid " + std::string(schema.getShortDisplayName().cStr()) +
                       ": " + kjText(e));
  } catch (const MessageError& e) {
    throw MessageError(what + ": " + e.what());
  }
}

void validateMessageTree(const MessageStorage& storage, const std::string& what) {
  try {
    (void)storage.root().targetSize();
  } catch (const kj::Exception& e) {
    throw MessageError(what + ": malformed message: " + kjText(e));
  } catch (const std::exception& e) {
    throwAsMessageError(what, e);
  }
}

std::shared_ptr<const MessageStorage> decodeMessage(std::span<const std::byte> bytes,
                                                    const std::string& what,
                                                    const DecodeLimits& limits) {
  if (bytes.empty()) throw MessageError(what + ": empty input, expected a Cap'n Proto message");
  if (bytes.size() > limits.max_bytes) {
    throw MessageError(what + ": " + std::to_string(bytes.size()) + " bytes exceeds the limit of " +
                       std::to_string(limits.max_bytes));
  }
  if (bytes.size() % sizeof(capnp::word) != 0) {
    throw MessageError(what + ": " + std::to_string(bytes.size()) +
                       " bytes is not a whole number of 8-byte words (truncated?)");
  }
  auto words = kj::heapArray<capnp::word>(bytes.size() / sizeof(capnp::word));
  std::memcpy(words.begin(), bytes.data(), bytes.size());
  return decodeMessageWords(kj::mv(words), what, limits);
}

std::shared_ptr<const MessageStorage> decodeMessageWords(kj::Array<capnp::word> words,
                                                         const std::string& what,
                                                         const DecodeLimits& limits) {
  if (words.size() == 0) throw MessageError(what + ": empty input, expected a Cap'n Proto message");
  if (words.size() * sizeof(capnp::word) > limits.max_bytes) {
    throw MessageError(what + ": " + std::to_string(words.size() * sizeof(capnp::word)) +
                       " bytes exceeds the limit of " + std::to_string(limits.max_bytes));
  }
  const std::size_t nwords = words.size();
  capnp::ReaderOptions options;
  options.traversalLimitInWords = limits.traversal_limit_words != 0
                                      ? limits.traversal_limit_words
                                      : std::max<std::uint64_t>(4 * nwords, 64 * 1024);
  options.nestingLimit = limits.nesting_limit;
  try {
    auto storage = std::make_shared<detail::FlatStorage>(kj::mv(words), options);
    // The whole tree is walked once here, so later readers only see bounds-checked data.
    (void)storage->root().targetSize();
    return storage;
  } catch (const kj::Exception& e) {
    throw MessageError(what + ": malformed message: " + kjText(e));
  }
}

std::vector<std::byte> encodeMessage(const MessageStorage& storage) {
  auto flat = capnp::messageToFlatArray(storage.segments());
  auto b = flat.asBytes();
  std::vector<std::byte> out(b.size());
  std::memcpy(out.data(), b.begin(), b.size());
  return out;
}

}  // namespace tessera
