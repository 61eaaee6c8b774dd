#include <tessera/memory/process_allocator.hpp>

#include <cstdlib>
#include <cstring>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace tessera::memory {

namespace {

/// True when the environment chooses this setting itself.
bool environmentSets(const char* variable, const char* tunable) {
  if (std::getenv(variable) != nullptr) return true;
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  return tunables != nullptr && std::strstr(tunables, tunable) != nullptr;
}

}  // namespace

AllocatorTuning tuneProcessAllocator() {
  AllocatorTuning done;
#if defined(__GLIBC__)
  if (!environmentSets("MALLOC_ARENA_MAX", "glibc.malloc.arena_max"))
    done.arenas_limited = mallopt(M_ARENA_MAX, kMallocArenas) == 1;
  if (!environmentSets("MALLOC_MMAP_THRESHOLD_", "glibc.malloc.mmap_threshold"))
    done.mmap_threshold_fixed =
        mallopt(M_MMAP_THRESHOLD, static_cast<int>(kMmapThresholdBytes)) == 1;
#endif
  return done;
}

}  // namespace tessera::memory
