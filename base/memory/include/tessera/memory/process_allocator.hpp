// tuneProcessAllocator: glibc malloc settings for a long-running process that hosts actors
// (docs/architecture.md#runtime, "Memory"). Call it once, first thing in main(), before any
// thread starts.
//
// Why: actors free on one thread what another allocated (messages, submaps, search pyramids of
// 1-10 MB), which glibc's defaults turn into resident memory that is never given back:
//   * one heap arena per thread (up to 8 per core), each keeping its own free pages: limited to
//     2 arenas (M_ARENA_MAX);
//   * a sliding mmap threshold: once a block mapped on its own is freed, glibc raises the
//     threshold to that block's size (up to 32 MiB), so later blocks of that size come from the
//     arenas and leave holes there when freed. The threshold is fixed at 128 KiB (glibc's
//     initial value), so blocks of that size and more are mapped on their own and unmapped when
//     freed (M_MMAP_THRESHOLD; fixing it also fixes the trim threshold at glibc's 128 KiB).
// A setting is left alone when the environment sets it (MALLOC_ARENA_MAX, MALLOC_MMAP_THRESHOLD_,
// or the matching glibc.malloc tunable in GLIBC_TUNABLES), so a user can still choose. Under a
// sanitizer, which brings its own allocator, the calls change nothing.
#pragma once

#include <cstddef>

namespace tessera::memory {

/// Arenas tuneProcessAllocator() allows.
inline constexpr int kMallocArenas = 2;
/// Blocks from this size on are mapped on their own by glibc once tuneProcessAllocator() ran.
inline constexpr std::size_t kMmapThresholdBytes = std::size_t{128} << 10;

/// What tuneProcessAllocator() did (false: left to the environment, or not glibc).
struct AllocatorTuning {
  bool arenas_limited = false;
  bool mmap_threshold_fixed = false;
};

AllocatorTuning tuneProcessAllocator();

}  // namespace tessera::memory
