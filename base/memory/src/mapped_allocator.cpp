// Big blocks straight from mmap(2), returned with munmap(2); see the header for why.
#include <tessera/memory/mapped_allocator.hpp>

#include <sys/mman.h>

namespace tessera::memory {

void* allocateMapped(std::size_t bytes) {
  if (bytes < kMappedMinBytes) return ::operator new(bytes == 0 ? 1 : bytes);
  void* block = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (block == MAP_FAILED) throw std::bad_alloc();
  return block;
}

void deallocateMapped(void* block, std::size_t bytes) noexcept {
  if (block == nullptr) return;
  if (bytes < kMappedMinBytes)
    ::operator delete(block);
  else
    (void)munmap(block, bytes);  // cannot fail for a whole block that mmap gave
}

}  // namespace tessera::memory
