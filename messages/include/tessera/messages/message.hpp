// Message<T>, Loan<T> and MessageStorage: how Tessera holds Cap'n Proto messages.
//
// A publisher asks for a Loan<T>, builds the message in place (a large Data payload it writes
// whole may go in a blob beside the message: Loan::blob()), and seals it into an immutable
// MessageStorage. Every subscriber then reads those same bytes through a Message<T>, which keeps
// the storage alive through a shared pointer: fan-out to N subscribers copies a pointer, never
// the payload. Bytes that come from outside (a file, another process, the network) enter through
// decodeMessage(), which checks them under traversal limits and turns malformed input into a
// MessageError instead of a crash.
//
// Ownership: MessageStorage is reference counted and immutable once sealed; a Message<T> is a
// cheap handle (one shared_ptr plus a Cap'n Proto reader). Readers are safe to use from any
// number of threads at once.
#pragma once

#include <capnp/any.h>
#include <capnp/message.h>
#include <capnp/orphan.h>
#include <capnp/schema.h>
#include <capnp/serialize.h>
#include <kj/exception.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace tessera {

/// Raised for bytes that are not a valid message (truncated, malformed, too large, wrong type).
class MessageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// A delivered message whose root cannot be read as its type (bytes from another process are
/// checked only as they are read): the runtime drops it with a warning instead of failing the
/// subscriber.
class MalformedMessage : public MessageError {
 public:
  using MessageError::MessageError;
};

/// Identity of a message type: Cap'n Proto schema id plus a readable name for errors.
struct MessageType {
  std::uint64_t id = 0;
  const char* name = "";
  friend bool operator==(const MessageType& a, const MessageType& b) { return a.id == b.id; }
};

/// The MessageType of a generated Cap'n Proto struct.
template <typename T>
MessageType messageTypeOf();

/// Immutable bytes of one Cap'n Proto message, shared by every reader of it.
class MessageStorage {
 public:
  virtual ~MessageStorage() = default;
  /// The root pointer; valid as long as this storage lives.
  virtual capnp::AnyPointer::Reader root() const = 0;
  /// The message's segments, e.g. for a recorder or a network bridge to write as-is.
  virtual kj::ArrayPtr<const kj::ArrayPtr<const capnp::word>> segments() const = 0;
  /// Total bytes over all segments.
  std::size_t sizeInBytes() const;
  /// Address of the first byte of the first segment (to check zero-copy delivery).
  const void* address() const;
};

namespace detail {
/// Storage a message is built in: the heap (BuilderStorage) or, for a topic that crosses
/// processes, a loaned shared-memory chunk (the runtime's transport provides that one).
class LoanStorage : public MessageStorage {
 public:
  virtual capnp::MessageBuilder& builder() = 0;
  /// Ends construction: records the segment table so readers never touch the builder state.
  virtual void seal() = 0;
  /// The uninitialised bytes reserved beside the message for one large Data field (see
  /// Loan::blob()); empty unless the loan asked for them. Word-aligned; owned by this storage.
  std::span<std::byte> blob() const { return blob_; }

 protected:
  std::span<std::byte> blob_;
};

/// Storage whose segments were allocated by a Cap'n Proto builder on the heap.
class BuilderStorage final : public LoanStorage {
 public:
  /// blob_bytes: uninitialised heap bytes to reserve for blob() (0: none).
  explicit BuilderStorage(std::size_t size_hint_bytes, std::size_t blob_bytes = 0);
  // Cap'n Proto destructors are noexcept(false); freeing heap segments cannot throw.
  ~BuilderStorage() noexcept override;
  capnp::MessageBuilder& builder() override { return *builder_; }
  void seal() override;
  capnp::AnyPointer::Reader root() const override;
  kj::ArrayPtr<const kj::ArrayPtr<const capnp::word>> segments() const override;

 private:
  // Small messages are built in this zeroed scratch block, so one allocation (the make_shared
  // that holds this object) serves both the control block and the first segment.
  static constexpr std::size_t kInlineWords = 48;
  capnp::word inline_[kInlineWords];
  // Larger first segments come zeroed from a process-wide pool and go back to it (Cap'n Proto
  // re-zeroes the used part when the builder dies), so a steady stream of large messages
  // reuses warm memory instead of paying mmap, page faults and munmap per message.
  capnp::word* pooled_ = nullptr;
  std::size_t pooled_words_ = 0;
  std::unique_ptr<capnp::word[]> blob_words_;           // outlives builder_, which may refer to it
  std::optional<capnp::MallocMessageBuilder> builder_;  // in place: no second allocation
  kj::ArrayPtr<const kj::ArrayPtr<const capnp::word>> segments_;
};

/// Allocates a BuilderStorage. Messages are usually freed on another thread than the one that
/// built them; a scalable allocator keeps that cross-thread free off a shared malloc arena lock.
std::shared_ptr<BuilderStorage> makeBuilderStorage(std::size_t size_hint_bytes,
                                                   std::size_t blob_bytes = 0);
}  // namespace detail

/// A read view of one message of type T. Copyable, cheap, thread-safe to read.
template <typename T>
class Message {
 public:
  using Reader = typename T::Reader;

  Message() = default;
  explicit Message(std::shared_ptr<const MessageStorage> storage)
      : storage_(std::move(storage)), reader_(storage_->root().template getAs<T>()) {}

  const Reader& operator*() const { return reader_; }
  const Reader* operator->() const { return &reader_; }
  const Reader& reader() const { return reader_; }
  const std::shared_ptr<const MessageStorage>& storage() const { return storage_; }
  explicit operator bool() const { return storage_ != nullptr; }

 private:
  std::shared_ptr<const MessageStorage> storage_;
  Reader reader_{};
};

/// A message under construction. Build it through ->, then hand it to Publisher::publish.
template <typename T>
class Loan {
 public:
  using Builder = typename T::Builder;

  /// size_hint_bytes: expected encoded size; large arrays fit in one segment when it is right.
  /// blob_bytes: reserve blob() (see there).
  explicit Loan(std::size_t size_hint_bytes = 0, std::size_t blob_bytes = 0)
      : Loan(detail::makeBuilderStorage(size_hint_bytes, blob_bytes)) {}
  /// Builds in storage provided by the caller (e.g. a shared-memory chunk).
  explicit Loan(std::shared_ptr<detail::LoanStorage> storage)
      : storage_(std::move(storage)), root_(storage_->builder().template initRoot<T>()) {}

  Builder& operator*() { return root_; }
  Builder* operator->() { return &root_; }
  Builder& builder() { return root_; }

  /// Makes the message a copy of `source` (to forward a received message with a field changed);
  /// the builder then edits the copy.
  void copyFrom(typename T::Reader source) {
    storage_->builder().setRoot(source);
    root_ = storage_->builder().template getRoot<T>();
  }

  /// Bytes for one large Data field, reserved with the loan (Publisher::loanWithBlob): placed
  /// after the message rather than inside it, and NOT zeroed, so a producer that overwrites a
  /// large payload anyway writes it once (a Data field from init...() is zeroed first, then
  /// filled). Write every byte (unwritten ones keep whatever an earlier message left there),
  /// then attach them with blobData(). Empty when the loan reserved none.
  std::span<std::byte> blob() { return storage_->blob(); }
  /// The blob as an orphan to adopt into the Data field (`loan->adoptImage(loan.blobData())`);
  /// at most once per loan. The field then reads back only through a Reader: getting its
  /// Builder throws, so keep writing through blob().
  capnp::Orphan<capnp::Data> blobData() {
    if (storage_->blob().empty()) throw std::logic_error("Loan::blobData(): no blob reserved");
    if (blob_taken_) throw std::logic_error("Loan::blobData(): the blob was already attached");
    blob_taken_ = true;
    const std::span<std::byte> b = storage_->blob();
    return storage_->builder().getOrphanage().referenceExternalData(
        capnp::Data::Reader(reinterpret_cast<const kj::byte*>(b.data()), b.size()));
  }

  /// Ends construction; the returned storage is immutable and shareable.
  std::shared_ptr<const MessageStorage> seal() && {
    root_ = Builder(nullptr);
    storage_->seal();
    return std::move(storage_);
  }

 private:
  std::shared_ptr<detail::LoanStorage> storage_;
  Builder root_;
  bool blob_taken_ = false;
};

/// Message<T> over `storage`; MalformedMessage when its root is not a readable T.
template <typename T>
Message<T> readMessage(std::shared_ptr<const MessageStorage> storage) {
  try {
    return Message<T>(std::move(storage));
  } catch (const kj::Exception& e) {
    throw MalformedMessage(std::string("not a readable ") + messageTypeOf<T>().name + ": " +
                           e.getDescription().cStr());
  }
}

/// Build a stand-alone message (tests, tools) and return its read view.
template <typename T, typename Fill>
Message<T> makeMessage(Fill&& fill, std::size_t size_hint_bytes = 0) {
  Loan<T> loan(size_hint_bytes);
  fill(*loan);
  return Message<T>(std::move(loan).seal());
}

/// Limits applied to bytes from outside the process.
struct DecodeLimits {
  std::size_t max_bytes = std::size_t{1} << 30;  ///< larger input is rejected
  std::uint64_t traversal_limit_words = 0;       ///< 0: 4x the message size, at least 64 Ki words
  int nesting_limit = 64;
};

/// Checks and adopts one message in Cap'n Proto's standard (unpacked) framing. The bytes are
/// copied once into aligned storage when not 8-byte aligned. `what` names the source in errors.
/// Throws MessageError on truncated or malformed input.
std::shared_ptr<const MessageStorage> decodeMessage(std::span<const std::byte> bytes,
                                                    const std::string& what,
                                                    const DecodeLimits& limits = {});

/// As decodeMessage, for framing bytes already in 8-byte words: adopts `words` (no copy; the
/// array's disposer runs when the last reader drops the message).
std::shared_ptr<const MessageStorage> decodeMessageWords(kj::Array<capnp::word> words,
                                                         const std::string& what,
                                                         const DecodeLimits& limits = {});

/// Checks that `storage` holds a readable T (every pointer in bounds, limits respected).
/// Throws MessageError naming `what` otherwise.
template <typename T>
Message<T> checkedMessage(std::shared_ptr<const MessageStorage> storage, const std::string& what);

/// Encodes a message in Cap'n Proto's standard framing (segment table + segments).
std::vector<std::byte> encodeMessage(const MessageStorage& storage);

// ---- implementation details ----

void validateMessageTree(const MessageStorage& storage, const std::string& what);
void validateTyped(const MessageStorage& storage, capnp::StructSchema schema,
                   const std::string& what);

template <typename T>
MessageType messageTypeOf() {
  return MessageType{capnp::typeId<T>(), capnp::Schema::from<T>().getShortDisplayName().cStr()};
}

template <typename T>
Message<T> checkedMessage(std::shared_ptr<const MessageStorage> storage, const std::string& what) {
  validateMessageTree(*storage, what);
  validateTyped(*storage, capnp::Schema::from<T>(), what);
  try {
    return readMessage<T>(std::move(storage));
  } catch (const MalformedMessage& e) {
    throw MessageError(what + ": " + e.what());
  }
}

}  // namespace tessera
