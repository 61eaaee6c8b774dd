// The allocator of message storages (the shared_ptr control block and the storage object):
// TBB's scalable allocator, whose per-thread caches make the allocation cheap on the hot path.
// Under ThreadSanitizer the default allocator instead: tbbmalloc is not instrumented, so TSan
// cannot see it hand a block freed by one thread to the thread that allocates it next, and
// reports the new object's construction as a race with the old one's destruction.
#pragma once

#include <memory>

#if defined(__SANITIZE_THREAD__)
namespace tessera::detail {
template <class T>
using StorageAllocator = std::allocator<T>;
}  // namespace tessera::detail
#else
#include <tbb/scalable_allocator.h>
namespace tessera::detail {
template <class T>
using StorageAllocator = tbb::scalable_allocator<T>;
}  // namespace tessera::detail
#endif
