// RouDiHost's process monitor: the ports of a process that died are freed, those of a process
// that is only stopped stay (with the messages waiting in its queue), however long it is stopped.
#include "processes.hpp"

#include <tessera/shm/roudi_host.hpp>

#include <poll.h>
#include <signal.h>
#include <unistd.h>
#include <catch2/catch.hpp>
#include <iceoryx_posh/popo/untyped_publisher.hpp>
#include <iceoryx_posh/popo/untyped_subscriber.hpp>
#include <iceoryx_posh/runtime/posh_runtime.hpp>

#include <chrono>
#include <string>
#include <thread>

using namespace tessera;
using namespace std::chrono_literals;

namespace {

const iox::capro::ServiceDescription kToFrozen{"tessera", "frozen", "capnp"};
const iox::capro::ServiceDescription kToDead{"tessera", "dead", "capnp"};

void registerAs(const std::string& name) {
  iox::runtime::PoshRuntime::initRuntime(
      iox::RuntimeName_t(iox::cxx::TruncateToCapacity, name.c_str()));
}

/// One byte from `fd`, or -1 when none comes within `timeout`.
int readByte(int fd, std::chrono::milliseconds timeout = 10s) {
  pollfd p{fd, POLLIN, 0};
  if (::poll(&p, 1, static_cast<int>(timeout.count())) != 1) return -1;
  unsigned char c = 0;
  return ::read(fd, &c, 1) == 1 ? c : -1;
}

void writeByte(int fd, unsigned char c) {
  (void)!::write(fd, &c, 1);
}

struct Pipe {
  Pipe() { REQUIRE(::pipe(fd) == 0); }
  ~Pipe() {
    ::close(fd[0]);
    ::close(fd[1]);
  }
  int in() const { return fd[0]; }
  int out() const { return fd[1]; }
  int fd[2] = {-1, -1};
};

/// Subscribes to `service` and says so on `ready`. Then, on any byte from `ask`, answers how
/// many chunks it finds in its queue (within 5 s, up to 5).
int subscriber(const std::string& name, const iox::capro::ServiceDescription& service, int ready,
               int ask, int answer) {
  registerAs(name);
  iox::popo::SubscriberOptions options;
  options.queueCapacity = 16;
  iox::popo::UntypedSubscriber sub(service, options);
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (sub.getSubscriptionState() != iox::SubscribeState::SUBSCRIBED) {
    if (std::chrono::steady_clock::now() > deadline) return 2;
    std::this_thread::sleep_for(5ms);
  }
  writeByte(ready, 'r');
  if (readByte(ask, 60s) < 0) return 3;
  int taken = 0;
  const auto until = std::chrono::steady_clock::now() + 5s;
  while (taken < 5 && std::chrono::steady_clock::now() < until) {
    sub.take()
        .and_then([&](const void* chunk) {
          ++taken;
          sub.release(chunk);
        })
        .or_else([](auto) { std::this_thread::sleep_for(5ms); });
  }
  writeByte(answer, static_cast<unsigned char>(taken));
  return 0;
}

/// Publishes to both services. On 's' answers which have a subscriber (bit 0: frozen, bit 1:
/// dead); on 'p' sends 5 chunks to the frozen one and answers 'p'; on 'q' leaves.
int publisher(int ask, int answer) {
  registerAs("tessera_test_publisher");
  iox::popo::UntypedPublisher to_frozen(kToFrozen);
  iox::popo::UntypedPublisher to_dead(kToDead);
  for (;;) {
    const int c = readByte(ask, 60s);
    if (c == 's') {
      writeByte(answer, (to_frozen.hasSubscribers() ? 1 : 0) | (to_dead.hasSubscribers() ? 2 : 0));
    } else if (c == 'p') {
      for (int i = 0; i < 5; ++i) {
        to_frozen.loan(8).and_then([&](void* chunk) { to_frozen.publish(chunk); });
      }
      writeByte(answer, 'p');
    } else {
      return c == 'q' ? 0 : 4;
    }
  }
}

}  // namespace

TEST_CASE("RouDi frees the ports of a dead process and keeps those of a stopped one", "[shm]") {
  Pipe ready, ask_frozen, frozen_answer, ask_publisher, publisher_answer;
  test::Children children;
  const pid_t frozen = children.spawn([&] {
    return subscriber("tessera_test_frozen", kToFrozen, ready.out(), ask_frozen.in(),
                      frozen_answer.out());
  });
  Pipe never;  // the dead subscriber is killed before anyone asks it
  const pid_t dead = children.spawn([&] {
    return subscriber("tessera_test_dead", kToDead, ready.out(), never.in(), never.out());
  });
  const pid_t publishing =
      children.spawn([&] { return publisher(ask_publisher.in(), publisher_answer.out()); });
  RouDiHostOptions options;
  options.pools = memPoolsFor({{1 << 10, 32}});
  RouDiHost roudi(options);
  children.open();
  REQUIRE(readByte(ready.in()) == 'r');
  REQUIRE(readByte(ready.in()) == 'r');
  auto connected = [&] {
    writeByte(ask_publisher.out(), 's');
    return readByte(publisher_answer.in());
  };
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (connected() != 3 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(20ms);
  }
  REQUIRE(connected() == 3);

  ::kill(frozen, SIGSTOP);
  ::kill(dead, SIGKILL);
  CHECK(children.wait(dead, 10s) == 128 + SIGKILL);
  std::this_thread::sleep_for(3500ms);  // more than twice RouDi's 1.5 s heartbeat timeout
  CHECK(connected() == 1);              // the stopped subscriber stays, the dead one is gone
  writeByte(ask_publisher.out(), 'p');
  CHECK(readByte(publisher_answer.in()) == 'p');
  ::kill(frozen, SIGCONT);
  writeByte(ask_frozen.out(), '?');
  CHECK(readByte(frozen_answer.in()) == 5);  // what was sent while it was stopped waited for it
  writeByte(ask_publisher.out(), 'q');
  CHECK(children.wait(publishing, 10s) == 0);
  CHECK(children.wait(frozen, 10s) == 0);
}
