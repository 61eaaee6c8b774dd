// LargePageAllocator: a standard allocator for big arrays read at scattered places (a planner's
// per-cell search state). Blocks of 2 MiB and more are 2 MiB-aligned and advised for
// transparent huge pages, so a search sweeping a wide region of a map takes far fewer TLB misses
// (docs/algorithms.md#global-planning). Smaller blocks come from operator new. Where the kernel
// has no transparent huge pages the advice is ignored and the memory is ordinary.
#pragma once

#include <tessera/memory/block_allocator.hpp>

#include <cstddef>
#include <vector>

namespace tessera::memory {

/// Blocks from this size on are aligned and advised.
inline constexpr std::size_t kLargePageBytes = std::size_t{1} << 21;

/// `bytes` of uninitialised memory; throws std::bad_alloc.
void* allocateLarge(std::size_t bytes);
/// Frees a block from allocateLarge(bytes) (the same `bytes`).
void deallocateLarge(void* block, std::size_t bytes) noexcept;

template <class T>
using LargePageAllocator = BlockAllocator<T, allocateLarge, deallocateLarge>;

template <class T>
using LargePageVector = std::vector<T, LargePageAllocator<T>>;

}  // namespace tessera::memory
