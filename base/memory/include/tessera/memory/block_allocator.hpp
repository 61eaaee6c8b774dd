// BlockAllocator: a standard allocator whose blocks come from a pair of functions
// `void* allocate(std::size_t bytes)` and `void deallocate(void* block, std::size_t bytes)`.
// The allocators of this folder (LargePageAllocator, MappedAllocator) are this template over
// their own pair; all instances are interchangeable (stateless).
#pragma once

#include <cstddef>
#include <new>

namespace tessera::memory {

template <class T, void* (*Allocate)(std::size_t), void (*Deallocate)(void*, std::size_t) noexcept>
struct BlockAllocator {
  using value_type = T;
  template <class U>
  struct rebind {
    using other = BlockAllocator<U, Allocate, Deallocate>;
  };

  BlockAllocator() = default;
  template <class U>
  BlockAllocator(const BlockAllocator<U, Allocate, Deallocate>& /*other*/) noexcept {}

  T* allocate(std::size_t n) {
    if (n > static_cast<std::size_t>(-1) / sizeof(T)) throw std::bad_array_new_length();
    return static_cast<T*>(Allocate(n * sizeof(T)));
  }
  void deallocate(T* p, std::size_t n) noexcept { Deallocate(p, n * sizeof(T)); }

  template <class U>
  bool operator==(const BlockAllocator<U, Allocate, Deallocate>& /*other*/) const noexcept {
    return true;
  }
};

}  // namespace tessera::memory
