// Large blocks: std::aligned_alloc at 2 MiB (its size a multiple of the alignment) and
// madvise(MADV_HUGEPAGE) before the first touch, so the kernel backs them with huge pages when
// transparent huge pages are "always" or "madvise".
#include <tessera/memory/large_page_allocator.hpp>

#include <cstdlib>

#include <sys/mman.h>

namespace tessera::memory {

namespace {

std::size_t roundedUp(std::size_t bytes) {
  return (bytes + kLargePageBytes - 1) / kLargePageBytes * kLargePageBytes;
}

}  // namespace

void* allocateLarge(std::size_t bytes) {
  if (bytes < kLargePageBytes) return ::operator new(bytes == 0 ? 1 : bytes);
  if (bytes > static_cast<std::size_t>(-1) - kLargePageBytes) throw std::bad_alloc();
  const std::size_t size = roundedUp(bytes);
  void* block = std::aligned_alloc(kLargePageBytes, size);
  if (block == nullptr) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
  // Advice only: without huge pages the block is ordinary memory, so a failure is ignored.
  (void)madvise(block, size, MADV_HUGEPAGE);
#endif
  return block;
}

void deallocateLarge(void* block, std::size_t bytes) noexcept {
  if (block == nullptr) return;
  if (bytes < kLargePageBytes)
    ::operator delete(block);
  else
    std::free(block);  // NOLINT(cppcoreguidelines-no-malloc): from std::aligned_alloc
}

}  // namespace tessera::memory
