// Hand-offs of shared-memory chunks made visible to ThreadSanitizer (scripts/tsan.sh).
// iceoryx passes a chunk from publisher to subscriber, and back to the pool, through lock-free
// queues in a library not built with TSan. When both ends live in one process, TSan then sees the
// writer's bytes and the reader's read with nothing ordering them. These mark the edges iceoryx
// provides: publish/release happen before take/loan of the same chunk. No-ops without TSan.
#pragma once

#if defined(__SANITIZE_THREAD__)
extern "C" void __tsan_acquire(void* addr);
extern "C" void __tsan_release(void* addr);
#endif

namespace tessera::detail {

/// Before a chunk leaves this thread (published, or returned to the pool).
inline void chunkHandedOff([[maybe_unused]] const void* payload) {
#if defined(__SANITIZE_THREAD__)
  __tsan_release(const_cast<void*>(payload));
#endif
}

/// After a chunk arrives in this thread (taken by a subscriber, or loaned from the pool).
inline void chunkTakenOver([[maybe_unused]] const void* payload) {
#if defined(__SANITIZE_THREAD__)
  __tsan_acquire(const_cast<void*>(payload));
#endif
}

}  // namespace tessera::detail
