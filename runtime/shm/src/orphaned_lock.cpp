#include <tessera/shm/orphaned_lock.hpp>

#include <linux/futex.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <climits>
#include <string>

namespace tessera {

namespace {
// glibc's __kind bits (nptl/pthreadP.h): the mutex type in the low bits, then these.
constexpr int kRobustBit = 16;
constexpr int kPriorityInheritBit = 32;
constexpr int kPriorityProtectBit = 64;
constexpr int kProcessSharedBit = 128;
}  // namespace

bool threadExists(int tid) {
  // /proc/<tid> answers for every thread, not only the main one of a process.
  return tid > 0 && ::access(("/proc/" + std::to_string(tid)).c_str(), F_OK) == 0;
}

bool releaseIfOwnerDied(pthread_mutex_t& mutex) {
  auto& d = mutex.__data;
  const int kind = __atomic_load_n(&d.__kind, __ATOMIC_RELAXED);
  if ((kind & (kRobustBit | kPriorityInheritBit | kPriorityProtectBit)) != 0) return false;
  const int owner = __atomic_load_n(&d.__owner, __ATOMIC_ACQUIRE);
  if (owner == 0 || threadExists(owner)) return false;
  // The owner's fields first, as its unlock would; then the lock word, and wake whoever waits
  // (2 = contended). A waiter swaps in 2 and, finding 0, owns the lock.
  d.__count = 0;
  d.__nusers = 0;
  __atomic_store_n(&d.__owner, 0, __ATOMIC_RELAXED);
  const int was = __atomic_exchange_n(&d.__lock, 0, __ATOMIC_RELEASE);
  if (was > 1) {
    const int op = (kind & kProcessSharedBit) != 0 ? FUTEX_WAKE : FUTEX_WAKE_PRIVATE;
    ::syscall(SYS_futex, &d.__lock, op, INT_MAX, nullptr, nullptr, 0);
  }
  return true;
}

}  // namespace tessera
