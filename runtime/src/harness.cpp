#include <tessera/runtime/harness.hpp>

#include "runtime_impl.hpp"

#include <stdexcept>

namespace tessera {

namespace {
/// The hidden actor that owns the harness's capture subscriptions; its mailboxes are wired
/// directly.
class CaptureActor final : public Actor {
 public:
  void configure(ActorContext&) override {}
};
}  // namespace

struct ActorHarness::Captures {
  std::map<std::string, std::vector<std::shared_ptr<const MessageStorage>>> by_topic;
  std::map<std::string, detail::TopicState*> inputs;
};

ActorHarness::ActorHarness(std::unique_ptr<Actor> actor, std::string output_dir, std::string name)
    : runtime_([&] {
        RuntimeOptions o;
        o.manual = true;
        o.show_progress = false;
        o.output_dir = std::move(output_dir);
        return o;
      }()),
      name_(std::move(name)),
      captures_(std::make_unique<Captures>()) {
  actor_ = &runtime_.add(name_, std::move(actor));
  runtime_.configure(/*allow_unpublished=*/true);
  auto& impl = *runtime_.impl_;
  // Every topic the actor publishes is captured by a reliable, unbounded subscription that
  // belongs to a hidden actor, so nothing it publishes is ever lost to the test.
  auto capture = std::make_unique<detail::ActorSlot>();
  capture->index = static_cast<std::uint32_t>(impl.actors.size());
  capture->name = "(harness capture)";
  capture->instance = std::make_unique<CaptureActor>();
  for (const auto& topic_name : impl.actors[0]->publishes) {
    auto& topic = *impl.topics.at(topic_name);
    auto* sink = &captures_->by_topic[topic_name];
    capture->subscriptions.push_back(detail::Subscription{
        topic_name, MailboxPolicy::reliable(std::size_t{1} << 40),
        [sink](const std::shared_ptr<const MessageStorage>& m) { sink->push_back(m); }});
    topic.subscribers.push_back(detail::Subscriber{
        capture->index, static_cast<std::uint32_t>(capture->subscriptions.size() - 1)});
  }
  impl.actors.push_back(std::move(capture));
}

ActorHarness::~ActorHarness() = default;

void ActorHarness::ensureStarted() {
  if (!started_) {
    runtime_.start();
    started_ = true;
  }
}

void ActorHarness::pushRaw(const std::string& topic, MessageType type,
                           std::shared_ptr<const MessageStorage> m) {
  ensureStarted();
  auto& impl = *runtime_.impl_;
  const std::string global = runtime_.globalTopic(name_, topic);
  auto it = impl.topics.find(global);
  if (it == impl.topics.end() || it->second->subscribers.empty()) {
    throw std::invalid_argument("ActorHarness: actor '" + name_ + "' does not subscribe to '" +
                                topic + "'");
  }
  if (!(it->second->type == type)) {
    throw std::invalid_argument("ActorHarness: topic '" + topic + "' carries " +
                                it->second->type.name + ", not " + type.name);
  }
  impl.publish(it->second.get(), detail::kExternalOwner, std::move(m));
}

void ActorHarness::advance(Nanos dt) {
  ensureStarted();
  const Nanos target = runtime_.clock().now() + dt;
  runtime_.runUntilIdle();
  while (runtime_.fireDueTimers(target)) runtime_.runUntilIdle();
}

void ActorHarness::stop() {
  ensureStarted();
  if (stopped_) return;
  stopped_ = true;
  runtime_.stop();
}

std::size_t ActorHarness::publishedCount(const std::string& topic) const {
  auto it = captures_->by_topic.find(runtime_.globalTopic(name_, topic));
  return it == captures_->by_topic.end() ? 0 : it->second.size();
}

const std::vector<std::shared_ptr<const MessageStorage>>& ActorHarness::capturedRaw(
    const std::string& topic, MessageType type) const {
  const std::string global = runtime_.globalTopic(name_, topic);
  auto it = captures_->by_topic.find(global);
  if (it == captures_->by_topic.end()) {
    throw std::invalid_argument("ActorHarness: actor '" + name_ + "' does not publish '" + topic +
                                "'");
  }
  const auto& t = *runtime_.impl_->topics.at(global);
  if (!(t.type == type)) {
    throw std::invalid_argument("ActorHarness: topic '" + topic + "' carries " + t.type.name +
                                ", not " + type.name);
  }
  return it->second;
}

}  // namespace tessera
