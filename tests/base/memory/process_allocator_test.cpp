// Tests for tuneProcessAllocator (process_allocator.hpp): large blocks are given back to the
// system when freed, even after a bigger block was freed, and the environment's settings win.
#include <tessera/memory/process_allocator.hpp>

#include <catch2/catch.hpp>

#include <cstdlib>
#include <cstring>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace {

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitizerAllocator = true;  // its own allocator: mallopt changes nothing
#else
constexpr bool kSanitizerAllocator = false;
#endif

/// Bytes glibc holds in blocks mapped on their own.
std::size_t ownMappedBytes() {
#if defined(__GLIBC__)
  return mallinfo2().hblkhd;
#else
  return 0;
#endif
}

/// Keeps the compiler from pairing a malloc with its free and dropping both.
void* volatile g_sink = nullptr;

}  // namespace

TEST_CASE("tuned allocator maps a 1 MiB block on its own after an 8 MiB block was freed",
          "[memory]") {
  if (std::getenv("MALLOC_MMAP_THRESHOLD_") != nullptr || std::getenv("GLIBC_TUNABLES") != nullptr)
    return;  // the environment chose (tested below)
  const tessera::memory::AllocatorTuning tuning = tessera::memory::tuneProcessAllocator();
  if (kSanitizerAllocator) return;
  REQUIRE(tuning.mmap_threshold_fixed);
  // With glibc's sliding threshold, freeing this block raises the threshold to 8 MiB and the
  // next 1 MiB block comes from an arena, where freeing it leaves a hole that stays resident.
  constexpr std::size_t kBig = std::size_t{8} << 20;
  constexpr std::size_t kMid = std::size_t{1} << 20;
  void* big = std::malloc(kBig);
  REQUIRE(big != nullptr);
  std::memset(big, 1, kBig);
  g_sink = big;
  std::free(big);
  const std::size_t before = ownMappedBytes();
  void* mid = std::malloc(kMid);
  REQUIRE(mid != nullptr);
  std::memset(mid, 2, kMid);
  g_sink = mid;
  CHECK(ownMappedBytes() >= before + kMid);
  std::free(mid);
  CHECK(ownMappedBytes() == before);  // unmapped: back to the system
}

TEST_CASE("tuned allocator leaves a setting the environment makes to the environment",
          "[memory]") {
  if (kSanitizerAllocator) return;
  const char* had = std::getenv("MALLOC_ARENA_MAX");
  setenv("MALLOC_ARENA_MAX", "4", 1);
  const tessera::memory::AllocatorTuning tuning = tessera::memory::tuneProcessAllocator();
  CHECK_FALSE(tuning.arenas_limited);
  if (had == nullptr) unsetenv("MALLOC_ARENA_MAX");
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  if (tunables == nullptr && std::getenv("MALLOC_MMAP_THRESHOLD_") == nullptr) {
    setenv("GLIBC_TUNABLES", "glibc.malloc.mmap_threshold=65536", 1);
    CHECK_FALSE(tessera::memory::tuneProcessAllocator().mmap_threshold_fixed);
    unsetenv("GLIBC_TUNABLES");
    CHECK(tessera::memory::tuneProcessAllocator().mmap_threshold_fixed);
  }
}
