// Recovery of inter-process mutexes whose owner died while holding them.
//
// iceoryx 2.0 guards every publisher's and subscriber's port with a plain (not robust)
// process-shared pthread mutex in shared memory. A process killed while it holds one (a publisher
// is inside one for every send) leaves it locked for ever: RouDi's clean-up of that process, its
// discovery loop and every peer touching the port then block (iceoryx issues #325, #779, #1711).
// The launcher, which hosts RouDi and reaps its workers, hands such locks back once the owner is
// gone: a dead thread can never unlock, so nobody else could have taken the lock meanwhile.
//
// glibc-specific: reads the owner's thread id from the mutex. Robust, priority-inheritance and
// priority-protected mutexes are left alone (the kernel or glibc handles their owners' death).
#pragma once

#include <pthread.h>

namespace tessera {

/// If `mutex` (process-shared) is held by a thread that no longer exists, marks it unlocked and
/// wakes its waiters, who then take it as usual; returns whether it did. The data the lock
/// guarded may be half-updated; the caller accepts that to keep the other processes running.
bool releaseIfOwnerDied(pthread_mutex_t& mutex);

/// True while a thread with this id exists on this machine (any process).
bool threadExists(int tid);

}  // namespace tessera
