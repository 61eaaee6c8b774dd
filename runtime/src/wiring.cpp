// Wiring: actors added to the runtime, the topics between them (one message type each), the
// ActorContext through which actors subscribe, advertise and set timers, the configure-time
// checks, the stop order, and the queries tools and tests make about the wiring.
#include "runtime_impl.hpp"

#include <algorithm>
#include <stdexcept>

namespace tessera {

using detail::ActorSlot;

detail::TopicState& Runtime::Impl::topic(const std::string& name, MessageType type,
                                         const std::string& who, bool publishing) {
  if (name.empty()) throw ConfigError("actor '" + who + "': empty topic name");
  if (publishing && type.id == kAnyMessageType.id)
    throw ConfigError("actor '" + who + "' publishes '" + name + "' without a message type");
  auto it = topics.find(name);
  if (it == topics.end()) {
    auto t = std::make_unique<detail::TopicState>();
    t->runtime = this;
    t->name = name;
    t->type = type;
    it = topics.emplace(name, std::move(t)).first;
  } else if (type.id == kAnyMessageType.id) {
    // An untyped subscriber accepts whatever the topic carries.
  } else if (it->second->type.id == kAnyMessageType.id) {
    it->second->type = type;  // an untyped subscriber came first
  } else if (!(it->second->type == type)) {
    throw ConfigError("topic '" + name + "': actor '" + who + "' " +
                      (publishing ? "publishes" : "subscribes to") + " it as " + type.name +
                      " but it already carries " + it->second->type.name);
  }
  if (publishing) it->second->publishers.push_back(who);
  return *it->second;
}

namespace detail {

void ActorSlotContext::addTimer(Nanos period, std::function<void()> callback, Nanos first_delay) {
  if (period <= 0) {
    throw ConfigError("actor '" + actor_.name + "': timer period must be > 0 ns, got " +
                      std::to_string(period));
  }
  std::lock_guard lock(rt_.timers_mutex);
  rt_.timers.push_back(Timer{actor_.index, period,
                             rt_.clock.now() + std::max<Nanos>(first_delay, 0),
                             std::move(callback)});
  actor_.timers.push_back(rt_.timers.size() - 1);
}

void ActorSlotContext::callAt(Nanos when, std::function<void()> callback) {
  std::lock_guard lock(rt_.timers_mutex);
  when = std::max(when, rt_.clock.now());
  for (auto index : actor_.timers) {
    auto& t = rt_.timers[index];
    if (t.period == 0 && t.next == Timer::kIdle && !t.queued && !t.callback) {
      t.next = when;
      t.callback = std::move(callback);
      return;
    }
  }
  rt_.timers.push_back(Timer{actor_.index, 0, when, std::move(callback)});
  actor_.timers.push_back(rt_.timers.size() - 1);
}

MessageType ActorSlotContext::topicType(std::string_view topic) const {
  auto it = rt_.topics.find(global(topic));
  if (it == rt_.topics.end())
    throw std::logic_error("actor '" + actor_.name + "': no topic '" + std::string(topic) + "'");
  return it->second->type;
}

void ActorSlotContext::declareFiniteSource() {
  if (!actor_.finite) {
    actor_.finite = true;
    ++rt_.finite_sources;
  }
}

void ActorSlotContext::finished() {
  if (actor_.finite && !actor_.done.exchange(true)) {
    actor_.progress = 1.0;
    ++rt_.finished_sources;
  }
}

void ActorSlotContext::reportProgress(double fraction) {
  actor_.progress = std::clamp(fraction, 0.0, 1.0);
}

RunSnapshot ActorSlotContext::snapshot() const {
  RunSnapshot r;
  // start_wall and start_sim are set before any actor's start(), so before any thread an
  // actor starts there could call this.
  r.wall_s = nanosToSeconds(steadyNow() - rt_.start_wall);
  r.sim_s = nanosToSeconds(rt_.clock.now() - rt_.start_sim);
  double progress = 0;
  int finite = 0;
  for (const auto& c : rt_.actors) {
    RunSnapshot::ActorFigures a;
    a.name = c->name;
    a.messages_in = c->messages_in.load();
    a.messages_out = c->messages_out.load();
    a.busy_s = nanosToSeconds(c->busy_ns.load(std::memory_order_relaxed));
    {
      std::lock_guard lock(c->mutex);
      for (const auto& s : c->subscriptions) a.drops += s.drops;
      a.queue_depth = c->queue.size();
      a.max_queue_depth = c->max_depth;
    }
    if (c->finite) {
      progress += c->progress.load();
      ++finite;
    }
    r.actors.push_back(std::move(a));
  }
  if (finite > 0) r.progress = progress / finite;
  return r;
}

void ActorSlotContext::requestStop(std::string_view reason) {
  rt_.requestStop("actor '" + actor_.name + "': " + std::string(reason));
}

std::string ActorSlotContext::global(std::string_view local) const {
  return actor_.globalName(std::string(local));
}

void ActorSlotContext::requireConfiguring(const char* what) const {
  if (!rt_.configuring && !rt_.options.manual) {
    throw std::logic_error("actor '" + actor_.name + "': " + what +
                           " is only allowed inside configure()");
  }
}

void ActorSlotContext::subscribeRaw(std::string_view topic, MessageType type, MailboxPolicy policy,
                                    RawHandler handler) {
  requireConfiguring("subscribe");
  used_.insert(std::string(topic));
  auto& t = rt_.topic(global(topic), type, actor_.name, false);
  actor_.subscriptions.push_back(Subscription{t.name, policy, std::move(handler)});
  t.subscribers.push_back(
      Subscriber{actor_.index, static_cast<std::uint32_t>(actor_.subscriptions.size() - 1)});
}

std::pair<TopicState*, std::uint32_t> ActorSlotContext::advertiseRaw(std::string_view topic,
                                                                     MessageType type) {
  requireConfiguring("advertise");
  used_.insert(std::string(topic));
  auto& t = rt_.topic(global(topic), type, actor_.name, true);
  actor_.publishes.push_back(t.name);
  return {&t, actor_.index};
}

}  // namespace detail

Actor& Runtime::add(std::string name, std::unique_ptr<Actor> actor,
                    std::map<std::string, std::string> remap, std::string topic_namespace) {
  if (impl_->configured) throw std::logic_error("Runtime::add after configure()");
  if (!actor) throw std::invalid_argument("Runtime::add: null actor '" + name + "'");
  for (const auto& c : impl_->actors) {
    if (c->name == name) throw ConfigError("two actors named '" + name + "'");
  }
  auto slot = std::make_unique<ActorSlot>();
  slot->index = static_cast<std::uint32_t>(impl_->actors.size());
  slot->name = std::move(name);
  slot->instance = std::move(actor);
  slot->remap = std::move(remap);
  slot->topic_namespace = std::move(topic_namespace);
  slot->context = std::make_unique<detail::ActorSlotContext>(*impl_, *slot);
  auto& ref = *slot->instance;
  impl_->actors.push_back(std::move(slot));
  return ref;
}

std::pair<detail::TopicState*, std::uint32_t> Runtime::externalAdvertise(const std::string& topic,
                                                                         MessageType type) {
  if (impl_->configured && !impl_->options.manual) {
    throw std::logic_error("external publishers must be created before configure()");
  }
  return {&impl_->topic(topic, type, "(external)", true), detail::kExternalOwner};
}

void Runtime::exportTopic(const std::string& topic, MessageType type,
                          std::shared_ptr<TopicExport> out) {
  if (impl_->configured) throw std::logic_error("exportTopic after configure()");
  if (!out) throw std::invalid_argument("exportTopic: null export for '" + topic + "'");
  auto& t = impl_->topic(topic, type, "(export)", false);
  t.exporter = std::move(out);
}

int Runtime::finiteSources() const {
  return impl_->finite_sources.load();
}

ImportFn Runtime::importTopic(const std::string& topic, MessageType type) {
  if (impl_->configured) throw std::logic_error("importTopic after configure()");
  auto* t = &impl_->topic(topic, type, "(import)", true);
  auto* rt = impl_.get();
  return [rt, t](std::shared_ptr<const MessageStorage> message, bool loopback,
                 ImportDelivery delivery) {
    rt->deliver(t, std::move(message), delivery);
    if (loopback) rt->releaseWork(1);
  };
}

void Runtime::configure(bool allow_unpublished) {
  if (impl_->configured) throw std::logic_error("Runtime::configure called twice");
  impl_->configuring = true;
  for (auto& c : impl_->actors) {
    try {
      c->instance->configure(*c->context);
    } catch (const ConfigError& e) {
      impl_->configuring = false;
      throw ConfigError("actor '" + c->name + "': " + e.what());
    }
    for (const auto& [local, global] : c->remap) {
      if (!c->context->used_.count(local)) {
        std::string used;
        for (const auto& u : c->context->used_) used += (used.empty() ? "" : ", ") + u;
        impl_->configuring = false;
        throw ConfigError("actor '" + c->name + "': remap of '" + local +
                          "' names no topic it uses (its topics: " + used + ")");
      }
    }
  }
  impl_->configuring = false;
  if (!allow_unpublished) {
    for (const auto& [name, t] : impl_->topics) {
      if (!t->publishers.empty() || t->subscribers.empty()) continue;
      if (std::all_of(t->subscribers.begin(), t->subscribers.end(), [&](const auto& s) {
            return impl_->actors[s.actor]->subscriptions[s.subscription].policy.optional;
          }))
        continue;  // only observers wait for it
      const auto& external = impl_->options.external_inputs;
      if (std::find(external.begin(), external.end(), name) != external.end()) continue;
      std::string who;
      for (const auto& s : t->subscribers) {
        who += (who.empty() ? "" : ", ") + impl_->actors[s.actor]->name;
      }
      throw ConfigError("topic '" + name + "' (" + t->type.name + ") is subscribed by " + who +
                        " but no actor publishes it; check the actor list and remaps");
    }
  }
  impl_->configured = true;
}

std::vector<std::uint32_t> Runtime::Impl::stopOrder() const {
  // Publishers stop before their subscribers, so a final publish in stop() still arrives.
  const auto n = actors.size();
  std::vector<std::set<std::uint32_t>> downstream(n);
  std::vector<int> indegree(n, 0);
  for (const auto& [name, t] : topics) {
    for (const auto& pub_name : t->publishers) {
      for (std::uint32_t p = 0; p < n; ++p) {
        if (actors[p]->name != pub_name) continue;
        for (const auto& s : t->subscribers) {
          if (s.actor != p && downstream[p].insert(s.actor).second) ++indegree[s.actor];
        }
      }
    }
  }
  std::vector<std::uint32_t> order;
  std::vector<bool> placed(n, false);
  while (order.size() < n) {
    bool progress = false;
    for (std::uint32_t i = 0; i < n; ++i) {
      if (placed[i] || indegree[i] != 0) continue;
      placed[i] = true;
      order.push_back(i);
      for (auto d : downstream[i]) --indegree[d];
      progress = true;
      break;
    }
    if (!progress) {  // a cycle: take the first remaining actor in registration order
      for (std::uint32_t i = 0; i < n; ++i) {
        if (placed[i]) continue;
        placed[i] = true;
        order.push_back(i);
        for (auto d : downstream[i]) --indegree[d];
        break;
      }
    }
  }
  return order;
}

std::string Runtime::globalTopic(const std::string& actor, const std::string& local) const {
  for (const auto& c : impl_->actors) {
    if (c->name != actor) continue;
    return c->globalName(local);
  }
  throw std::invalid_argument("no actor named '" + actor + "'");
}

std::vector<std::string> Runtime::subscriptionsOf(const std::string& actor) const {
  for (const auto& c : impl_->actors) {
    if (c->name != actor) continue;
    std::vector<std::string> out;
    for (const auto& s : c->subscriptions) out.push_back(s.topic);
    return out;
  }
  throw std::invalid_argument("no actor named '" + actor + "'");
}

std::vector<std::string> Runtime::stopOrder() const {
  std::vector<std::string> out;
  for (auto i : impl_->stopOrder()) out.push_back(impl_->actors[i]->name);
  return out;
}

std::vector<std::string> Runtime::publicationsOf(const std::string& actor) const {
  for (const auto& c : impl_->actors) {
    if (c->name == actor) return c->publishes;
  }
  throw std::invalid_argument("no actor named '" + actor + "'");
}

std::vector<std::string> Runtime::topicsOfType(MessageType type) const {
  std::vector<std::string> out;
  for (const auto& [name, t] : impl_->topics) {
    if (t->type == type) out.push_back(name);
  }
  return out;
}

MessageType Runtime::topicType(const std::string& topic) const {
  auto it = impl_->topics.find(topic);
  if (it == impl_->topics.end()) throw std::invalid_argument("no topic named '" + topic + "'");
  return it->second->type;
}

MailboxPolicy Runtime::subscriptionPolicy(const std::string& actor,
                                          const std::string& topic) const {
  for (const auto& c : impl_->actors) {
    if (c->name != actor) continue;
    for (const auto& s : c->subscriptions) {
      if (s.topic == topic) return s.policy;
    }
  }
  throw std::invalid_argument("actor '" + actor + "' does not subscribe to '" + topic + "'");
}

}  // namespace tessera
