// LargePageAllocator: a standard allocator for big arrays read at scattered places (a planner's
// per-cell search state). Blocks of 2 MiB and more are 2 MiB-aligned and advised for
// transparent huge pages, so a search sweeping a wide region of a map takes far fewer TLB misses
// (docs/algorithms.md#global-planning). Smaller blocks come from operator new. Where the kernel
// has no transparent huge pages the advice is ignored and the memory is ordinary.
#pragma once

#include <cstddef>
#include <new>
#include <vector>

namespace tessera::memory {

/// Blocks from this size on are aligned and advised.
inline constexpr std::size_t kLargePageBytes = std::size_t{1} << 21;

/// `bytes` of uninitialised memory; throws std::bad_alloc.
void* allocateLarge(std::size_t bytes);
/// Frees a block from allocateLarge(bytes) (the same `bytes`).
void deallocateLarge(void* block, std::size_t bytes) noexcept;

template <class T>
struct LargePageAllocator {
  using value_type = T;

  LargePageAllocator() = default;
  template <class U>
  LargePageAllocator(const LargePageAllocator<U>& /*other*/) noexcept {}

  T* allocate(std::size_t n) {
    if (n > static_cast<std::size_t>(-1) / sizeof(T)) throw std::bad_array_new_length();
    return static_cast<T*>(allocateLarge(n * sizeof(T)));
  }
  void deallocate(T* p, std::size_t n) noexcept { deallocateLarge(p, n * sizeof(T)); }

  template <class U>
  bool operator==(const LargePageAllocator<U>& /*other*/) const noexcept {
    return true;
  }
};

template <class T>
using LargePageVector = std::vector<T, LargePageAllocator<T>>;

}  // namespace tessera::memory
