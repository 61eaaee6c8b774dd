#include "processes.hpp"

#include <tessera/shm/orphaned_lock.hpp>
#include <tessera/shm/roudi_host.hpp>

#include <sys/mman.h>
#include <unistd.h>
#include <catch2/catch.hpp>
#include <iceoryx_posh/internal/popo/building_blocks/locking_policy.hpp>
#include <iceoryx_posh/internal/popo/ports/publisher_port_data.hpp>
#include <iceoryx_posh/popo/untyped_publisher.hpp>
#include <iceoryx_posh/popo/untyped_subscriber.hpp>
#include <iceoryx_posh/runtime/posh_runtime.hpp>

#include <atomic>
#include <chrono>
#include <string>
#include <thread>

using namespace tessera;
using namespace std::chrono_literals;

namespace {
/// A process-shared mutex (recursive, like iceoryx's port locks) in memory a forked child shares.
struct SharedMutex {
  SharedMutex() {
    void* p = ::mmap(nullptr, sizeof(pthread_mutex_t), PROT_READ | PROT_WRITE,
                     MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    REQUIRE(p != MAP_FAILED);
    mutex = static_cast<pthread_mutex_t*>(p);
    pthread_mutexattr_t attr;
    pthread_mutexattr_init(&attr);
    pthread_mutexattr_setpshared(&attr, PTHREAD_PROCESS_SHARED);
    pthread_mutexattr_settype(&attr, PTHREAD_MUTEX_RECURSIVE);
    pthread_mutex_init(mutex, &attr);
    pthread_mutexattr_destroy(&attr);
  }
  ~SharedMutex() { ::munmap(mutex, sizeof(pthread_mutex_t)); }
  pthread_mutex_t* mutex = nullptr;
};

}  // namespace

TEST_CASE("a lock whose owner process died is handed to the thread waiting for it", "[shm]") {
  SharedMutex shared;
  int locked[2];
  REQUIRE(::pipe(locked) == 0);
  test::Children children;
  const pid_t child = children.spawn([&] {
    pthread_mutex_lock(shared.mutex);
    (void)!::write(locked[1], "x", 1);
    std::this_thread::sleep_for(1s);
    return 0;  // exits still holding it
  });
  children.open();
  char c;
  REQUIRE(::read(locked[0], &c, 1) == 1);
  std::atomic<bool> got{false};
  std::thread waiter([&] {
    pthread_mutex_lock(shared.mutex);  // blocks: the child holds it
    got = true;
    pthread_mutex_unlock(shared.mutex);
  });
  std::this_thread::sleep_for(100ms);
  CHECK_FALSE(releaseIfOwnerDied(*shared.mutex));  // the owner still runs
  CHECK_FALSE(got.load());
  REQUIRE(children.wait(child, 10s) == 0);
  CHECK_FALSE(threadExists(child));
  std::this_thread::sleep_for(100ms);
  CHECK_FALSE(got.load());  // nobody else can ever unlock it
  CHECK(releaseIfOwnerDied(*shared.mutex));
  waiter.join();
  CHECK(got.load());
  // Back to a normal lock, usable by this process.
  CHECK(pthread_mutex_trylock(shared.mutex) == 0);
  CHECK(pthread_mutex_unlock(shared.mutex) == 0);
  CHECK_FALSE(releaseIfOwnerDied(*shared.mutex));  // free: nothing to do
  CHECK(pthread_mutex_destroy(shared.mutex) == 0);
  for (int fd : locked) ::close(fd);
}

TEST_CASE("a free lock and one held by a live thread are left alone", "[shm]") {
  SharedMutex shared;
  CHECK_FALSE(releaseIfOwnerDied(*shared.mutex));
  REQUIRE(pthread_mutex_lock(shared.mutex) == 0);
  CHECK(threadExists(static_cast<int>(::gettid())));
  CHECK_FALSE(releaseIfOwnerDied(*shared.mutex));
  CHECK(pthread_mutex_unlock(shared.mutex) == 0);
}

namespace {
/// A publisher that can take its own port lock, as a send does.
struct LockablePublisher : iox::popo::UntypedPublisher {
  using iox::popo::UntypedPublisher::UntypedPublisher;
  void takePortLock() {
    struct Members : iox::popo::BasePort {
      static iox::popo::BasePortData* of(iox::popo::BasePort& port) {
        auto members =
            static_cast<iox::popo::BasePortData* (iox::popo::BasePort::*)()>(&Members::getMembers);
        return (port.*members)();
      }
    };
    auto* data = static_cast<iox::popo::PublisherPortData*>(Members::of(port()));
    static_cast<const iox::popo::ThreadSafePolicy&>(data->m_chunkSenderData).lock();
  }
};

const iox::capro::ServiceDescription kService{"tessera", "t", "capnp"};

void initRuntime(const std::string& name) {
  iox::runtime::PoshRuntime::initRuntime(
      iox::RuntimeName_t(iox::cxx::TruncateToCapacity, name.c_str()));
}

/// Publishes one chunk to itself on kService; 0 when it arrives, 2 when the ports never
/// connect (RouDi's discovery is stuck), 3 when the chunk does not arrive.
int publishAndReceiveOne() {
  initRuntime("tessera_test_after");
  iox::popo::UntypedSubscriber sub(kService);
  iox::popo::UntypedPublisher pub(kService);
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (sub.getSubscriptionState() != iox::SubscribeState::SUBSCRIBED || !pub.hasSubscribers()) {
    if (std::chrono::steady_clock::now() > deadline) return 2;
    std::this_thread::sleep_for(5ms);
  }
  pub.loan(8).and_then([&](void* p) { pub.publish(p); });
  while (std::chrono::steady_clock::now() < deadline + 5s) {
    bool got = false;
    sub.take().and_then([&](const void* p) {
      got = true;
      sub.release(p);
    });
    if (got) return 0;
    std::this_thread::sleep_for(5ms);
  }
  return 3;
}
}  // namespace

TEST_CASE("a process killed holding its port lock does not wedge RouDi once the lock is released",
          "[shm]") {
  int locked[2], go[2];
  REQUIRE(::pipe(locked) == 0);
  REQUIRE(::pipe(go) == 0);
  test::Children children;
  const pid_t holder = children.spawn([&] {
    initRuntime("tessera_test_holder");
    LockablePublisher pub(kService);
    pub.takePortLock();  // and is killed before it lets go, like a kill -9 inside a send
    (void)!::write(locked[1], "x", 1);
    std::this_thread::sleep_for(60s);
    return 1;
  });
  const pid_t after = children.spawn([&] {
    char c;
    if (::read(go[0], &c, 1) != 1) return 4;
    return publishAndReceiveOne();
  });
  RouDiHostOptions options;
  options.pools = memPoolsFor({{1 << 10, 16}});
  RouDiHost roudi(options);
  children.open();
  char c;
  REQUIRE(::read(locked[0], &c, 1) == 1);
  CHECK(roudi.releaseOrphanedPortLocks().empty());  // its owner still runs
  ::kill(holder, SIGKILL);
  CHECK(children.wait(holder, 10s) == 128 + SIGKILL);
  const auto released = roudi.releaseOrphanedPortLocks();
  REQUIRE(released.size() == 1);
  CHECK(released[0] == "publisher 't' of tessera_test_holder");
  // RouDi's discovery and its clean-up of the dead process go on: a new pair of ports connects.
  (void)!::write(go[1], "x", 1);
  CHECK(children.wait(after, 30s) == 0);
  for (int fd : {locked[0], locked[1], go[0], go[1]}) ::close(fd);
}
