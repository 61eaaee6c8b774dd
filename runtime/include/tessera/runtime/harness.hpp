// ActorHarness: unit-test one actor without threads. Build it from the actor (or its options),
// push messages into the topics it subscribes to, step it deterministically on a simulated
// clock, and read everything it published.
//
//   ActorHarness h(std::make_unique<GridMapperActor>(opts));
//   h.push<msg::LaserScan>("scan", [&](auto b) { ... });
//   h.runUntilIdle();
//   auto maps = h.published<msg::OccupancyGrid>("map");
#pragma once

#include <tessera/runtime/runtime.hpp>

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace tessera {

class ActorHarness {
 public:
  explicit ActorHarness(std::unique_ptr<Actor> actor, std::string output_dir = "",
                        std::string name = "actor_under_test");
  ~ActorHarness();

  Actor& actor() { return *actor_; }
  Runtime& runtime() { return runtime_; }

  /// Publishes one message on the actor's local topic `topic` (queued, not yet handled).
  template <typename T, typename Fill>
  void push(const std::string& topic, Fill&& fill) {
    Loan<T> loan;
    fill(*loan);
    pushRaw(topic, messageTypeOf<T>(), std::move(loan).seal());
  }
  template <typename T>
  void push(const std::string& topic, const Message<T>& m) {
    pushRaw(topic, messageTypeOf<T>(), m.storage());
  }

  /// Handles queued messages until none is left; returns how many.
  std::size_t runUntilIdle() { return runtime_.runUntilIdle(); }
  /// Handles exactly one queued message; false when idle.
  bool step() { return runtime_.step(); }
  /// Moves simulated time forward by dt, firing due timers in order and draining after each.
  void advance(Nanos dt);
  Nanos now() const { return runtime_.clock().now(); }
  /// Calls the actor's stop() (which may publish) and drains.
  void stop();

  /// Everything the actor published on its local topic `topic`, oldest first.
  template <typename T>
  std::vector<Message<T>> published(const std::string& topic) const {
    std::vector<Message<T>> out;
    for (const auto& s : capturedRaw(topic, messageTypeOf<T>())) out.emplace_back(s);
    return out;
  }
  std::size_t publishedCount(const std::string& topic) const;

 private:
  void ensureStarted();
  void pushRaw(const std::string& topic, MessageType type, std::shared_ptr<const MessageStorage> m);
  const std::vector<std::shared_ptr<const MessageStorage>>& capturedRaw(const std::string& topic,
                                                                        MessageType type) const;
  Runtime runtime_;
  Actor* actor_;
  std::string name_;
  bool started_ = false, stopped_ = false;
  struct Captures;
  std::unique_ptr<Captures> captures_;
};

}  // namespace tessera
