// Mailboxes and strands: how a published message reaches its subscribers' inboxes (mailbox
// policies, back-pressure, fan-out sharing one message), and how an actor's inbox is drained
// on its strand, one handler at a time. The message path is kept in one file on purpose: it is
// the latency path of every message.
#include "runtime_impl.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <stdexcept>

namespace tessera {
namespace detail {

thread_local std::vector<const ActorSlot*> t_running;  // actors whose handlers run on this thread

std::shared_ptr<LoanStorage> loanStorage(TopicState* topic, std::size_t size_hint_bytes,
                                         std::size_t blob_bytes) {
  if (topic != nullptr && topic->exporter)
    return topic->exporter->loan(size_hint_bytes, blob_bytes);
  return makeBuilderStorage(size_hint_bytes, blob_bytes);
}

void publishRaw(TopicState* topic, std::uint32_t owner, std::shared_ptr<const MessageStorage> m) {
  if (topic == nullptr) throw std::logic_error("publish on an unadvertised Publisher");
  topic->runtime->publish(topic, owner, std::move(m));
}
std::uint64_t nextSeq(TopicState* topic) {
  return topic->seq.fetch_add(1);
}
const std::string& topicName(const TopicState* topic) {
  return topic->name;
}

}  // namespace detail

using detail::ActorSlot;
using detail::Item;

void Runtime::Impl::publish(detail::TopicState* topic, std::uint32_t owner,
                            std::shared_ptr<const MessageStorage> message) {
  if (owner != detail::kExternalOwner) ++actors[owner]->messages_out;
  topic->published.fetch_add(1, std::memory_order_relaxed);
  topic->published_bytes.fetch_add(message->sizeInBytes(), std::memory_order_relaxed);
  if (topic->exporter) {
    // A message coming back to this process is work in flight: the run is not idle until the
    // import has queued it.
    const bool loops = topic->exporter->loopsBack();
    if (loops) pending.fetch_add(1);
    bool sent = false;
    try {
      sent = topic->exporter->send(message);
    } catch (...) {
      if (loops) releaseWork(1);
      throw;
    }
    if (sent) return;
    // Not sent (the transport is cut off from the other processes): it will not come back, so
    // this process's own subscribers get it here.
    if (loops) releaseWork(1);
  }
  deliver(topic, std::move(message));
}

void Runtime::Impl::deliver(detail::TopicState* topic,
                            std::shared_ptr<const MessageStorage> message,
                            ImportDelivery delivery) {
  if (!started || options.manual) delivery = ImportDelivery::kSchedule;
  if (closed.load()) return;  // after the run: nothing would handle it
  const auto n = topic->subscribers.size();
  if (message && delivery == ImportDelivery::kRunHere && n == 1) {
    // The common case of a message arriving after a quiet spell: no queue round trip, whose
    // locks and allocations are all cold cache lines on the latency path.
    const auto& sub = topic->subscribers[0];
    if (runNow(*actors[sub.actor], static_cast<std::int32_t>(sub.subscription), message)) return;
  }
  if (message) {
    for (std::size_t i = 0; i < n; ++i) {
      const auto& sub = topic->subscribers[i];
      // The last subscriber takes the publisher's reference; the others share it (zero copy).
      Item item{static_cast<std::int32_t>(sub.subscription), 0,
                i + 1 == n ? std::move(message) : message};
      enqueue(*actors[sub.actor], std::move(item), delivery == ImportDelivery::kSchedule);
    }
  }
  if (delivery != ImportDelivery::kRunHere) return;
  for (std::size_t i = 0; i < n; ++i) {
    ActorSlot& actor = *actors[topic->subscribers[i].actor];
    // A busy strand's runner may be past its last look at the inbox: schedule another drain.
    if (!drainIfFree(actor)) schedule(actor);
  }
}

void Runtime::Impl::enqueue(ActorSlot& actor, Item item, bool schedule_it) {
  std::unique_lock lock(actor.mutex);
  if (item.subscription >= 0) {
    auto& mailbox = actor.subscriptions[static_cast<std::size_t>(item.subscription)];
    if (mailbox.policy.kind == MailboxPolicy::Kind::kKeepLatest) {
      if (mailbox.queued >= mailbox.policy.capacity) {
        // Evict this subscription's oldest message; other subscriptions keep their order.
        auto victim = std::find_if(actor.queue.begin(), actor.queue.end(), [&](const Item& q) {
          return q.subscription == item.subscription;
        });
        actor.queue.erase(victim);
        --mailbox.queued;
        ++mailbox.drops;
        pending.fetch_sub(1);  // the evicted item will never run
      }
    } else {
      while (mailbox.queued >= mailbox.policy.capacity) {
        if (closed.load()) return;  // the run ended while this import waited for room
        if (std::find(detail::t_running.begin(), detail::t_running.end(), &actor) !=
            detail::t_running.end()) {
          throw std::logic_error("reliable mailbox '" + mailbox.topic + "' of actor '" +
                                 actor.name +
                                 "' is full and is being filled from its own handler chain; "
                                 "raise its capacity or break the reliable cycle");
        }
        if (actor.strand.try_lock()) {
          // Nobody runs the consumer right now: run it here instead of waiting for a worker.
          lock.unlock();
          drainLocked(actor, mailbox.policy.capacity);
          actor.strand.unlock();
          lock.lock();
          continue;
        }
        ++actor.waiting_publishers;
        actor.space.wait_for(lock, std::chrono::milliseconds(1));
        --actor.waiting_publishers;
      }
    }
    ++mailbox.queued;
  }
  if (options.manual) item.order = order_counter.fetch_add(1);
  if (item.subscription >= 0) item.enqueued = steadyNow();
  pending.fetch_add(1);
  actor.queue.push_back(std::move(item));
  actor.max_depth = std::max<std::uint64_t>(actor.max_depth, actor.queue.size());
  lock.unlock();
  if (schedule_it && !options.manual && started) schedule(actor);
}

void Runtime::Impl::schedule(ActorSlot& actor) {
  // The plain load skips a contended read-modify-write while a drain is already queued; it is
  // safe because the drain re-checks the queue under the inbox mutex before it lets go.
  if (!actor.scheduled.load(std::memory_order_relaxed) && !actor.scheduled.exchange(true)) {
    if (pool) {
      pool->post(actor);
    } else {
      arena->enqueue([this, &actor] { drainTask(actor); });
    }
  }
}

void Runtime::Impl::drainTask(ActorSlot& actor) {
  actor.scheduled.store(false);
  drainIfFree(actor);  // when another thread drains, it re-checks on release
}

bool Runtime::Impl::drainIfFree(ActorSlot& actor) {
  if (!actor.strand.try_lock()) return false;
  drainLocked(actor, 64);
  releaseStrand(actor);
  return true;
}

void Runtime::Impl::releaseStrand(ActorSlot& actor) {
  actor.strand.unlock();
  // A message that arrived meanwhile found the strand taken and relies on its holder to look.
  std::unique_lock lock(actor.mutex);
  const bool more = !actor.queue.empty();
  lock.unlock();
  if (more) schedule(actor);
}

bool Runtime::Impl::runNow(ActorSlot& actor, std::int32_t subscription,
                           std::shared_ptr<const MessageStorage>& message) {
  if (!actor.strand.try_lock()) return false;
  {
    std::lock_guard lock(actor.mutex);
    if (!actor.queue.empty()) {
      actor.strand.unlock();
      return false;
    }
  }
  pending.fetch_add(1);  // as if queued: the run is not idle while the handler runs
  detail::t_running.push_back(&actor);
  Item item{subscription, 0, std::move(message)};
  try {
    dispatch(actor, item);
  } catch (...) {
    detail::t_running.pop_back();
    releaseWork(1);
    actor.strand.unlock();
    throw;
  }
  item.message.reset();
  detail::t_running.pop_back();
  releaseWork(1);
  releaseStrand(actor);
  return true;
}

std::size_t Runtime::Impl::drainLocked(ActorSlot& actor, std::size_t budget) {
  detail::t_running.push_back(&actor);
  // Items are taken in small batches under one lock: under load this halves the lock traffic
  // between a publisher and its consumer.
  constexpr std::size_t kBatch = 16;
  std::array<Item, kBatch> batch;
  std::size_t done = 0;
  while (done < budget) {
    std::size_t n = 0;
    bool wake_publishers = false;
    {
      std::lock_guard lock(actor.mutex);
      // A publisher blocked on a full reliable mailbox is woken once its mailbox is half
      // empty (or the inbox is), not after every batch: each wake-up is a futex call on both
      // sides, and waking per batch made a fast publisher and its consumer ping-pong.
      bool half_empty = false;
      while (n < kBatch && done + n < budget && !actor.queue.empty()) {
        Item& item = batch[n++];
        item = std::move(actor.queue.front());
        actor.queue.pop_front();
        if (item.subscription >= 0) {
          auto& mailbox = actor.subscriptions[static_cast<std::size_t>(item.subscription)];
          --mailbox.queued;
          half_empty = half_empty || mailbox.queued <= mailbox.policy.capacity / 2;
        }
      }
      wake_publishers = actor.waiting_publishers > 0 && (half_empty || actor.queue.empty());
    }
    if (n == 0) break;
    if (wake_publishers) actor.space.notify_all();
    for (std::size_t i = 0; i < n; ++i) {
      try {
        dispatch(actor, batch[i]);
      } catch (...) {
        detail::t_running.pop_back();
        // The rest of the batch is dropped with the exception; keep the idle count right.
        releaseWork(n);
        throw;
      }
      batch[i].message.reset();
    }
    // Once per batch: the count is shared with every publisher, so per-item updates would
    // bounce its cache line between cores.
    releaseWork(n);
    done += n;
  }
  detail::t_running.pop_back();
  return done;
}

void Runtime::Impl::dispatch(ActorSlot& actor, Item& item) {
  const Nanos t0 = steadyNow();
  if (item.subscription >= 0) {
    // Indexed anew after the handler: in manual mode it may subscribe, moving the vector.
    const auto subscription = static_cast<std::size_t>(item.subscription);
    ++actor.messages_in;
    ++actor.subscriptions[subscription].handled;
    actor.queue_wait.add(item.enqueued > 0 ? t0 - item.enqueued : 0);
    try {
      actor.subscriptions[subscription].handler(item.message);
    } catch (const MalformedMessage& e) {
      // Bytes from outside that passed the transport's checks but not the reader's: the run
      // goes on without them; said (the first few) and counted, never silent.
      if (++actor.malformed <= 3) {
        std::fprintf(stderr, "warning: actor '%s' dropped a malformed message on '%s': %s\n",
                     actor.name.c_str(), actor.subscriptions[subscription].topic.c_str(), e.what());
      }
    } catch (const std::exception& e) {
      requestStop("actor '" + actor.name + "' failed handling '" +
                  actor.subscriptions[subscription].topic + "': " + e.what());
    }
  } else {
    const auto index = static_cast<std::size_t>(-item.subscription - 1);
    std::function<void()>* callback;
    std::function<void()> one_shot;  // moved out so the callback may schedule the next one
    {
      std::lock_guard lock(timers_mutex);
      timers[index].queued = false;
      if (timers[index].period == 0) {
        one_shot = std::move(timers[index].callback);
        timers[index].callback = nullptr;
        callback = &one_shot;
      } else {
        callback = &timers[index].callback;
      }
    }
    ++actor.timer_calls;
    try {
      (*callback)();
    } catch (const std::exception& e) {
      requestStop("actor '" + actor.name + "' failed in a timer: " + e.what());
    }
  }
  const Nanos took = steadyNow() - t0;
  actor.handler_time.add(took);
  actor.busy_ns.fetch_add(took, std::memory_order_relaxed);
}

void Runtime::Impl::releaseWork(std::size_t n) {
  const auto k = static_cast<std::int64_t>(n);
  if (pending.fetch_sub(k) == k) {
    std::lock_guard lock(idle_mutex);
    idle_cv.notify_all();
  }
}

void Runtime::Impl::waitIdle() {
  std::unique_lock lock(idle_mutex);
  while (pending.load() != 0) idle_cv.wait_for(lock, std::chrono::milliseconds(20));
}

bool Runtime::Impl::stepOne() {
  ActorSlot* best = nullptr;
  std::uint64_t best_order = 0;
  for (auto& c : actors) {
    std::lock_guard lock(c->mutex);
    if (!c->queue.empty() && (best == nullptr || c->queue.front().order < best_order)) {
      best = c.get();
      best_order = c->queue.front().order;
    }
  }
  if (best == nullptr) return false;
  std::lock_guard strand(best->strand);
  drainLocked(*best, 1);
  return true;
}

}  // namespace tessera
