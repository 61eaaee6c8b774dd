// `bench ipc` wire format: the header every payload starts with (whatever the transport), the
// payload sizes measured, and how a message's payload is written before it is sent (--fill).
// Every transport's leader and follower read and write these bytes; nothing here sends.
#pragma once

#include <tessera/runtime/clock.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <set>
#include <utility>

namespace tessera::app::ipc {

constexpr std::array<std::size_t, 4> kSizes{64, std::size_t{4} << 10, std::size_t{1} << 20,
                                            std::size_t{4} << 20};
constexpr std::size_t kStreamBytes = 64;

/// What building a message writes (--fill).
enum class Fill {
  kFirstUse,  // a buffer in full when it is first used (its pages faulted in), then its header
  kEvery,     // every message's payload in full
};

inline const char* fillName(Fill f) {
  return f == Fill::kEvery ? "every" : "first-use";
}

// kPrepare asks the follower to build its next pong (of `value` bytes) and answer kReady, so
// that no payload is written on either side while a ping or pong is under way.
enum class Kind : std::uint32_t { kPing, kPong, kPrepare, kReady, kStream, kStreamEnd, kQuit };

/// First bytes of every payload, whatever the transport.
struct Wire {
  Nanos stamp = 0;  // sender's steady clock right before publish/send
  // pong: the ping's one-way latency [ns]; answer to kStreamEnd: messages counted; kPrepare:
  // size of the pong to build.
  std::int64_t value = 0;
  std::uint64_t copies = 0;  // pong: the follower's messages copied so far (ours only)
  std::uint32_t bytes = 0;   // payload size, this header included
  Kind kind = Kind::kPing;
};
static_assert(sizeof(Wire) <= kSizes[0]);

inline Wire readWire(const void* p) {
  Wire w;
  std::memcpy(&w, p, sizeof w);
  return w;
}

inline void writeWire(void* p, const Wire& w) {
  std::memcpy(p, &w, sizeof w);
}

/// Stamps the Wire at `p` with the steady clock now, as the last thing before sending it.
inline Nanos stampWire(void* p) {
  Wire w = readWire(p);
  w.stamp = steadyNow();
  writeWire(p, w);
  return w.stamp;
}

/// Writes payloads as --fill says; one per process side, as it remembers what it wrote.
class PayloadFiller {
 public:
  explicit PayloadFiller(Fill fill) : fill_(fill) {}
  /// Writes the `bytes` at `p` (in full when the mode asks for it) and their Wire header.
  void operator()(void* p, std::size_t bytes, Kind kind, std::int64_t value = 0) {
    if (fill_ == Fill::kEvery || written_.insert({p, bytes}).second) std::memset(p, 0x5a, bytes);
    Wire w;
    w.bytes = static_cast<std::uint32_t>(bytes);
    w.kind = kind;
    w.value = value;
    writeWire(p, w);
  }

 private:
  Fill fill_;
  std::set<std::pair<const void*, std::size_t>> written_;  // first-use: buffers written in full
};

/// Small control messages (kPrepare, kReady, stream counts).
constexpr std::size_t kControlBytes = 64;

}  // namespace tessera::app::ipc
