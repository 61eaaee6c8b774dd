// The chunk-extent protocol of the shared-memory transport: a reused chunk is zero wherever a
// Cap'n Proto builder may write, while only what earlier uses wrote gets zeroed again.
#include <tessera/shm/shm_transport.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <cstddef>
#include <vector>

using namespace tessera;
using detail::chunkExtent;
using detail::recordChunkExtent;
using detail::zeroChunkForBuilder;

namespace {

constexpr std::size_t kCapacity = 4096;

bool zeroIn(const std::vector<std::byte>& b, std::size_t from, std::size_t to) {
  return std::all_of(b.begin() + static_cast<long>(from), b.begin() + static_cast<long>(to),
                     [](std::byte x) { return x == std::byte{0}; });
}

void scribble(std::vector<std::byte>& b, std::size_t from, std::size_t to) {
  std::fill(b.begin() + static_cast<long>(from), b.begin() + static_cast<long>(to),
            std::byte{0x5a});
}

}  // namespace

TEST_CASE("a chunk of unknown history is zeroed throughout before a builder uses it",
          "[shm][chunk_extent]") {
  std::vector<std::byte> chunk(kCapacity, std::byte{0x77});  // e.g. written by a foreign user
  CHECK(chunkExtent(chunk.data(), kCapacity) == kCapacity);
  const std::size_t rest = zeroChunkForBuilder(chunk.data(), kCapacity, 1024, 3);
  CHECK(rest == 0);
  CHECK(zeroIn(chunk, 16, kCapacity));
  // Until the message is sent, the whole builder range counts as written.
  CHECK(chunkExtent(chunk.data(), kCapacity) == 1024);
}

TEST_CASE("a reused chunk has only its recorded extent zeroed again", "[shm][chunk_extent]") {
  std::vector<std::byte> chunk(kCapacity, std::byte{0});
  zeroChunkForBuilder(chunk.data(), kCapacity, 2048, 0);
  scribble(chunk, 16, 200);  // the message that was sent used 200 bytes
  recordChunkExtent(chunk.data(), 0, 200);
  // Bytes past the extent are not touched (a marker there stays; the protocol says they are
  // zero, and this shows that the zeroing does not pay for them).
  chunk[3000] = std::byte{1};
  const std::size_t rest = zeroChunkForBuilder(chunk.data(), kCapacity, 2048, 1);
  CHECK(rest == 0);
  CHECK(zeroIn(chunk, 16, 2048));
  CHECK(chunk[3000] == std::byte{1});
}

TEST_CASE("an extent past the builder range is kept for the next use", "[shm][chunk_extent]") {
  std::vector<std::byte> chunk(kCapacity, std::byte{0});
  zeroChunkForBuilder(chunk.data(), kCapacity, kCapacity, 0);
  scribble(chunk, 16, 3000);
  recordChunkExtent(chunk.data(), 0, 3000);
  // A small message now: only its range is zeroed, and 3000 stays the extent.
  const std::size_t rest = zeroChunkForBuilder(chunk.data(), kCapacity, 512, 0);
  CHECK(rest == 3000);
  CHECK(zeroIn(chunk, 16, 512));
  CHECK(chunkExtent(chunk.data(), kCapacity) == 3000);
  // A large one next: everything the builder may use is zero again.
  zeroChunkForBuilder(chunk.data(), kCapacity, kCapacity, 0);
  CHECK(zeroIn(chunk, 16, kCapacity));
}

TEST_CASE("a prefix whose check value does not match counts as unknown history",
          "[shm][chunk_extent]") {
  std::vector<std::byte> chunk(kCapacity, std::byte{0});
  recordChunkExtent(chunk.data(), 0, 100);
  scribble(chunk, 16, kCapacity);
  chunk[8] ^= std::byte{0x01};  // extent field damaged
  CHECK(chunkExtent(chunk.data(), kCapacity) == kCapacity);
  zeroChunkForBuilder(chunk.data(), kCapacity, 256, 0);
  CHECK(zeroIn(chunk, 16, kCapacity));
  // An extent beyond the chunk cannot be right either.
  recordChunkExtent(chunk.data(), 0, kCapacity + 8);
  CHECK(chunkExtent(chunk.data(), kCapacity) == kCapacity);
}

TEST_CASE("a large span is zeroed exactly, whatever its alignment", "[shm][chunk_extent]") {
  // Spans this large take the streaming-store path; its unaligned head and tail must be exact.
  constexpr std::size_t kLarge = (std::size_t{1} << 20) + 100;
  for (std::size_t offset : {0u, 1u, 8u, 13u}) {
    INFO("offset " << offset);
    std::vector<std::byte> buffer(kLarge + 64, std::byte{0x77});
    std::byte* chunk = buffer.data() + offset;
    const std::size_t end = kLarge - 37;
    zeroChunkForBuilder(chunk, kLarge, end, 1);  // unknown history: zeroed throughout
    CHECK(zeroIn(buffer, offset + 16, offset + kLarge));
    CHECK(buffer[offset + kLarge] == std::byte{0x77});  // not one byte past the chunk
    CHECK(chunkExtent(chunk, kLarge) == end);
    // Reused: only the recorded extent is zeroed again.
    scribble(buffer, offset + 16, offset + end);
    zeroChunkForBuilder(chunk, kLarge, end, 1);
    CHECK(zeroIn(buffer, offset + 16, offset + kLarge));
  }
}

TEST_CASE("bytes a producer writes past the builder range without zeroing count as written",
          "[shm][chunk_extent]") {
  std::vector<std::byte> chunk(kCapacity, std::byte{0});
  zeroChunkForBuilder(chunk.data(), kCapacity, kCapacity, 0);
  recordChunkExtent(chunk.data(), 0, 100);
  chunk[3000] = std::byte{1};  // past the extent: not zeroed, not written by the next use
  // A blob loan: the builder may write to 512, the producer writes a blob up to 2048 unzeroed.
  const std::size_t rest = zeroChunkForBuilder(chunk.data(), kCapacity, 512, 0, 2048);
  CHECK(rest == 0);
  CHECK(zeroIn(chunk, 16, 512));
  CHECK(chunk[3000] == std::byte{1});
  // Were the producer to die now, the next use must know the blob's bytes are dirty.
  CHECK(chunkExtent(chunk.data(), kCapacity) == 2048);
  scribble(chunk, 512, 2048);
  zeroChunkForBuilder(chunk.data(), kCapacity, kCapacity, 0);
  CHECK(zeroIn(chunk, 16, 2048));
}
