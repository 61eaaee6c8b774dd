// MappedAllocator: a standard allocator for big arrays that are built, kept a while and dropped
// (a loop detector's cached matching pyramids). Blocks of kMappedMinBytes and more are mapped
// from the kernel on their own and unmapped when freed, so their memory leaves the process at
// once. From malloc they would leave holes in its heap that stay resident, and freeing them
// would raise glibc's mmap threshold for every later block (docs/benchmarks.md, "the state one
// submap at a time"). Smaller blocks come from operator new.
#pragma once

#include <tessera/memory/block_allocator.hpp>

#include <cstddef>
#include <vector>

namespace tessera::memory {

/// Blocks from this size on are mapped on their own.
inline constexpr std::size_t kMappedMinBytes = std::size_t{64} << 10;

/// `bytes` of memory (zero-filled when mapped); throws std::bad_alloc.
void* allocateMapped(std::size_t bytes);
/// Frees a block from allocateMapped(bytes) (the same `bytes`).
void deallocateMapped(void* block, std::size_t bytes) noexcept;

template <class T>
using MappedAllocator = BlockAllocator<T, allocateMapped, deallocateMapped>;

template <class T>
using MappedVector = std::vector<T, MappedAllocator<T>>;

}  // namespace tessera::memory
