#include "runtime_impl.hpp"

#include <tessera/runtime/process_stats.hpp>

#include <pthread.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <iomanip>
#include <set>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace tessera {
namespace detail {

// ---------------------------------------------------------------- histogram

void DurationHistogram::add(Nanos ns) {
  const auto v = static_cast<std::uint64_t>(std::max<Nanos>(ns, 0));
  int index;
  if (v < 16) {
    index = static_cast<int>(v);
  } else {
    const int e = 63 - std::countl_zero(v);  // >= 4
    const int sub = static_cast<int>((v >> (e - 3)) & 7);
    index = std::min(16 + (e - 4) * 8 + sub, kBuckets - 1);
  }
  ++counts_[static_cast<std::size_t>(index)];
  ++count_;
  total_ns_ += static_cast<Nanos>(v);
}

double DurationHistogram::percentileMicros(double q) const {
  if (count_ == 0) return 0.0;
  const auto target = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(count_)));
  std::uint64_t seen = 0;
  for (int i = 0; i < kBuckets; ++i) {
    seen += counts_[static_cast<std::size_t>(i)];
    if (seen >= std::max<std::uint64_t>(target, 1)) {
      if (i < 16) return i * 1e-3;
      const int e = (i - 16) / 8 + 4, sub = (i - 16) % 8;
      const double lo = std::ldexp(1.0, e) * (1.0 + sub / 8.0);
      const double hi = std::ldexp(1.0, e) * (1.0 + (sub + 1) / 8.0);
      return 0.5 * (lo + hi) * 1e-3;
    }
  }
  return 0.0;
}

// ---------------------------------------------------------------- context

thread_local std::vector<const Cell*> t_running;  // cells whose handlers run on this thread

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

using detail::Cell;
using detail::Item;

// ---------------------------------------------------------------- impl

Runtime::Impl::Impl(RuntimeOptions o)
    : options(std::move(o)), clock(options.clock, options.sim_start) {}

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

void Runtime::Impl::publish(detail::TopicState* topic, std::uint32_t owner,
                            std::shared_ptr<const MessageStorage> message) {
  if (owner != detail::kExternalOwner) ++cells[owner]->messages_out;
  if (topic->exporter) {
    // A message coming back to this process is work in flight: the run is not idle until the
    // import has queued it.
    const bool loops = topic->exporter->loopsBack();
    if (loops) pending.fetch_add(1);
    try {
      topic->exporter->send(message);
    } catch (...) {
      if (loops) releaseWork(1);
      throw;
    }
    return;
  }
  deliver(topic, std::move(message));
}

void Runtime::Impl::deliver(detail::TopicState* topic,
                            std::shared_ptr<const MessageStorage> message,
                            ImportDelivery delivery) {
  if (!started || options.manual) delivery = ImportDelivery::kSchedule;
  const auto n = topic->subscribers.size();
  if (message && delivery == ImportDelivery::kRunHere && n == 1) {
    // The common case of a message arriving after a quiet spell: no queue round trip, whose
    // locks and allocations are all cold cache lines on the latency path.
    const auto& sub = topic->subscribers[0];
    if (runNow(*cells[sub.cell], static_cast<std::int32_t>(sub.slot), message)) return;
  }
  if (message) {
    for (std::size_t i = 0; i < n; ++i) {
      const auto& sub = topic->subscribers[i];
      // The last subscriber takes the publisher's reference; the others share it (zero copy).
      Item item{static_cast<std::int32_t>(sub.slot), 0, i + 1 == n ? std::move(message) : message};
      enqueue(*cells[sub.cell], std::move(item), delivery == ImportDelivery::kSchedule);
    }
  }
  if (delivery != ImportDelivery::kRunHere) return;
  for (std::size_t i = 0; i < n; ++i) {
    Cell& cell = *cells[topic->subscribers[i].cell];
    // A busy strand's runner may be past its last look at the inbox: schedule another drain.
    if (!drainIfFree(cell)) schedule(cell);
  }
}

void Runtime::Impl::enqueue(Cell& cell, Item item, bool schedule_it) {
  std::unique_lock lock(cell.mutex);
  if (item.slot >= 0) {
    auto& slot = cell.slots[static_cast<std::size_t>(item.slot)];
    if (slot.policy.kind == MailboxPolicy::Kind::kKeepLatest) {
      if (slot.queued >= slot.policy.capacity) {
        // Evict this subscription's oldest message; other subscriptions keep their order.
        auto victim = std::find_if(cell.queue.begin(), cell.queue.end(),
                                   [&](const Item& q) { return q.slot == item.slot; });
        cell.queue.erase(victim);
        --slot.queued;
        ++slot.drops;
        pending.fetch_sub(1);  // the evicted item will never run
      }
    } else {
      while (slot.queued >= slot.policy.capacity) {
        if (std::find(detail::t_running.begin(), detail::t_running.end(), &cell) !=
            detail::t_running.end()) {
          throw std::logic_error("reliable mailbox '" + slot.topic + "' of actor '" + cell.name +
                                 "' is full and is being filled from its own handler chain; "
                                 "raise its capacity or break the reliable cycle");
        }
        if (cell.strand.try_lock()) {
          // Nobody runs the consumer right now: run it here instead of waiting for a worker.
          lock.unlock();
          drainLocked(cell, slot.policy.capacity);
          cell.strand.unlock();
          lock.lock();
          continue;
        }
        ++cell.waiting_publishers;
        cell.space.wait_for(lock, std::chrono::milliseconds(1));
        --cell.waiting_publishers;
      }
    }
    ++slot.queued;
  }
  if (options.manual) item.order = order_counter.fetch_add(1);
  pending.fetch_add(1);
  cell.queue.push_back(std::move(item));
  cell.max_depth = std::max<std::uint64_t>(cell.max_depth, cell.queue.size());
  lock.unlock();
  if (schedule_it && !options.manual && started) schedule(cell);
}

void Runtime::Impl::schedule(Cell& cell) {
  // The plain load skips a contended read-modify-write while a drain is already queued; it is
  // safe because the drain re-checks the queue under the inbox mutex before it lets go.
  if (!cell.scheduled.load(std::memory_order_relaxed) && !cell.scheduled.exchange(true)) {
    if (pool) {
      pool->post(cell);
    } else {
      arena->enqueue([this, &cell] { drainTask(cell); });
    }
  }
}

namespace detail {
StrandPool::StrandPool(int threads, std::function<void(Cell&)> drain) : drain_(std::move(drain)) {
  for (int i = 0; i < threads; ++i) {
    threads_.emplace_back([this, i] {
      // Named so that top -H, gdb and perf sched show which thread is the pool's.
      pthread_setname_np(pthread_self(), ("tessera-pool-" + std::to_string(i)).c_str());
      loop();
    });
  }
}
StrandPool::~StrandPool() {
  std::vector<Sleeper*> wake;
  {
    std::lock_guard lock(mutex_);
    quit_ = true;
    wake.swap(sleeping_);
  }
  for (Sleeper* s : wake) {
    s->handed = nullptr;
    s->woken.store(1, std::memory_order_release);
    s->woken.notify_one();
  }
  for (auto& t : threads_) t.join();
}
void StrandPool::post(Cell& cell) {
  Sleeper* wake = nullptr;
  {
    std::lock_guard lock(mutex_);
    post_rate_.post(steadyNow());
    if (sleeping_.empty()) {
      ready_.push_back(&cell);
      ready_count_.store(ready_.size(), std::memory_order_release);
    } else {
      wake = sleeping_.back();
      sleeping_.pop_back();
    }
  }
  if (wake) {
    wake->handed = &cell;
    wake->woken.store(1, std::memory_order_release);
    wake->woken.notify_one();
  }
}
void StrandPool::loop() {
  Sleeper self;
  std::unique_lock lock(mutex_);
  while (true) {
    if (ready_.empty()) {
      if (quit_) return;
      // Under a steady stream the next strand arrives within microseconds: poll briefly before
      // paying for a futex sleep and wake-up (yielding, so a publisher on this core still runs).
      lock.unlock();
      const Nanos spin_until = steadyNow() + (post_rate_.steady() ? kSpinNanos : 0);
      while (ready_count_.load(std::memory_order_acquire) == 0 && steadyNow() < spin_until) {
        std::this_thread::yield();
      }
      lock.lock();
      if (!ready_.empty() || quit_) continue;
      self.woken.store(0, std::memory_order_relaxed);
      sleeping_.push_back(&self);
      lock.unlock();
      while (self.woken.load(std::memory_order_acquire) == 0) self.woken.wait(0);
      if (self.handed == nullptr) return;  // the pool is shutting down
      drain_(*self.handed);
      lock.lock();
      continue;
    }
    Cell* cell = ready_.front();
    ready_.pop_front();
    ready_count_.store(ready_.size(), std::memory_order_release);
    lock.unlock();
    drain_(*cell);
    lock.lock();
  }
}
}  // namespace detail

void Runtime::Impl::drainTask(Cell& cell) {
  cell.scheduled.store(false);
  drainIfFree(cell);  // when another thread drains, it re-checks on release
}

bool Runtime::Impl::drainIfFree(Cell& cell) {
  if (!cell.strand.try_lock()) return false;
  drainLocked(cell, 64);
  releaseStrand(cell);
  return true;
}

void Runtime::Impl::releaseStrand(Cell& cell) {
  cell.strand.unlock();
  // A message that arrived meanwhile found the strand taken and relies on its holder to look.
  std::unique_lock lock(cell.mutex);
  const bool more = !cell.queue.empty();
  lock.unlock();
  if (more) schedule(cell);
}

bool Runtime::Impl::runNow(Cell& cell, std::int32_t slot,
                           std::shared_ptr<const MessageStorage>& message) {
  if (!cell.strand.try_lock()) return false;
  {
    std::lock_guard lock(cell.mutex);
    if (!cell.queue.empty()) {
      cell.strand.unlock();
      return false;
    }
  }
  pending.fetch_add(1);  // as if queued: the run is not idle while the handler runs
  detail::t_running.push_back(&cell);
  Item item{slot, 0, std::move(message)};
  try {
    dispatch(cell, item);
  } catch (...) {
    detail::t_running.pop_back();
    releaseWork(1);
    cell.strand.unlock();
    throw;
  }
  item.message.reset();
  detail::t_running.pop_back();
  releaseWork(1);
  releaseStrand(cell);
  return true;
}

std::size_t Runtime::Impl::drainLocked(Cell& cell, std::size_t budget) {
  detail::t_running.push_back(&cell);
  // Items are taken in small batches under one lock: under load this halves the lock traffic
  // between a publisher and its consumer.
  constexpr std::size_t kBatch = 16;
  std::array<Item, kBatch> batch;
  std::size_t done = 0;
  while (done < budget) {
    std::size_t n = 0;
    bool wake_publishers = false;
    {
      std::lock_guard lock(cell.mutex);
      // A publisher blocked on a full reliable mailbox is woken once its mailbox is half
      // empty (or the inbox is), not after every batch: each wake-up is a futex call on both
      // sides, and waking per batch made a fast publisher and its consumer ping-pong.
      bool half_empty = false;
      while (n < kBatch && done + n < budget && !cell.queue.empty()) {
        Item& item = batch[n++];
        item = std::move(cell.queue.front());
        cell.queue.pop_front();
        if (item.slot >= 0) {
          auto& slot = cell.slots[static_cast<std::size_t>(item.slot)];
          --slot.queued;
          half_empty = half_empty || slot.queued <= slot.policy.capacity / 2;
        }
      }
      wake_publishers = cell.waiting_publishers > 0 && (half_empty || cell.queue.empty());
    }
    if (n == 0) break;
    if (wake_publishers) cell.space.notify_all();
    for (std::size_t i = 0; i < n; ++i) {
      try {
        dispatch(cell, batch[i]);
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

void Runtime::Impl::dispatch(Cell& cell, Item& item) {
  const Nanos t0 = steadyNow();
  if (item.slot >= 0) {
    ++cell.messages_in;
    try {
      cell.slots[static_cast<std::size_t>(item.slot)].handler(item.message);
    } catch (const MalformedMessage& e) {
      // Bytes from outside that passed the transport's checks but not the reader's: the run
      // goes on without them; said (the first few) and counted, never silent.
      if (++cell.malformed <= 3) {
        std::fprintf(stderr, "warning: actor '%s' dropped a malformed message on '%s': %s\n",
                     cell.name.c_str(),
                     cell.slots[static_cast<std::size_t>(item.slot)].topic.c_str(), e.what());
      }
    } catch (const std::exception& e) {
      requestStop("actor '" + cell.name + "' failed handling '" +
                  cell.slots[static_cast<std::size_t>(item.slot)].topic + "': " + e.what());
    }
  } else {
    const auto index = static_cast<std::size_t>(-item.slot - 1);
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
    ++cell.timer_calls;
    try {
      (*callback)();
    } catch (const std::exception& e) {
      requestStop("actor '" + cell.name + "' failed in a timer: " + e.what());
    }
  }
  cell.handler_time.add(steadyNow() - t0);
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
  Cell* best = nullptr;
  std::uint64_t best_order = 0;
  for (auto& c : cells) {
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

void Runtime::Impl::queueTimer(std::size_t index) {
  std::uint32_t cell;
  {
    std::lock_guard lock(timers_mutex);
    auto& t = timers[index];
    if (t.queued) {
      ++t.overruns;
      return;
    }
    t.queued = true;
    cell = t.cell;
  }
  enqueue(*cells[cell], Item{-static_cast<std::int32_t>(index) - 1, 0, nullptr});
}

void Runtime::Impl::requestStop(const std::string& reason) {
  {
    std::lock_guard lock(stop_reason_mutex);
    if (stop_reason.empty()) stop_reason = reason;
  }
  stop_requested.store(true);
}

std::vector<std::uint32_t> Runtime::Impl::stopOrder() const {
  // Publishers stop before their subscribers, so a final publish in stop() still arrives.
  const auto n = cells.size();
  std::vector<std::set<std::uint32_t>> downstream(n);
  std::vector<int> indegree(n, 0);
  for (const auto& [name, t] : topics) {
    for (const auto& pub_name : t->publishers) {
      for (std::uint32_t p = 0; p < n; ++p) {
        if (cells[p]->name != pub_name) continue;
        for (const auto& s : t->subscribers) {
          if (s.cell != p && downstream[p].insert(s.cell).second) ++indegree[s.cell];
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

RunReport Runtime::Impl::makeReport() const {
  RunReport r;
  r.wall_s = nanosToSeconds(steadyNow() - start_wall);
  r.cpu_s = processCpuSeconds() - start_cpu;
  r.sim_duration_s = nanosToSeconds(clock.now() - start_sim);
  r.peak_rss_mb = peakRssMegabytes();
  r.interrupted = stop_requested.load();
  r.stop_reason = stop_reason;
  for (const auto& c : cells) {
    ActorReport a;
    a.name = c->name;
    a.messages_in = c->messages_in;
    a.messages_out = c->messages_out;
    a.timer_calls = c->timer_calls;
    a.malformed = c->malformed;
    for (const auto& s : c->slots) a.drops += s.drops;
    a.max_queue_depth = c->max_depth;
    a.handler_p50_us = c->handler_time.percentileMicros(0.50);
    a.handler_p99_us = c->handler_time.percentileMicros(0.99);
    a.handler_total_s = c->handler_time.totalSeconds();
    c->actor->summarize(a.summary);
    r.actors.push_back(std::move(a));
  }
  return r;
}

// ---------------------------------------------------------------- runtime

Runtime::Runtime(RuntimeOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}

Runtime::~Runtime() {
  if (impl_->arena || impl_->pool) {
    impl_->stop_requested = true;
    impl_->waitIdle();
  }
}

Actor& Runtime::add(std::string name, std::unique_ptr<Actor> actor,
                    std::map<std::string, std::string> remap) {
  if (impl_->configured) throw std::logic_error("Runtime::add after configure()");
  if (!actor) throw std::invalid_argument("Runtime::add: null actor '" + name + "'");
  for (const auto& c : impl_->cells) {
    if (c->name == name) throw ConfigError("two actors named '" + name + "'");
  }
  auto cell = std::make_unique<Cell>();
  cell->index = static_cast<std::uint32_t>(impl_->cells.size());
  cell->name = std::move(name);
  cell->actor = std::move(actor);
  cell->remap = std::move(remap);
  cell->context = std::make_unique<detail::CellContext>(*impl_, *cell);
  auto& ref = *cell->actor;
  impl_->cells.push_back(std::move(cell));
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
  for (auto& c : impl_->cells) {
    try {
      c->actor->configure(*c->context);
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
      std::string who;
      for (const auto& s : t->subscribers) {
        who += (who.empty() ? "" : ", ") + impl_->cells[s.cell]->name;
      }
      throw ConfigError("topic '" + name + "' (" + t->type.name + ") is subscribed by " + who +
                        " but no actor publishes it; check the actor list and remaps");
    }
  }
  impl_->configured = true;
}

void Runtime::start() {
  if (!impl_->configured) configure();
  if (impl_->started) return;
  impl_->start_sim = impl_->clock.now();
  impl_->start_wall = steadyNow();
  impl_->start_cpu = processCpuSeconds();
  if (!impl_->options.manual) {
    const int threads = impl_->options.threads > 0
                            ? impl_->options.threads
                            : static_cast<int>(std::max(2u, std::thread::hardware_concurrency()));
    if (impl_->options.executor == RuntimeOptions::Executor::kThreadPool) {
      impl_->pool = std::make_unique<detail::StrandPool>(
          threads, [rt = impl_.get()](Cell& c) { rt->drainTask(c); });
    } else {
      // The arena's threads are all TBB workers (the caller only waits), so lift TBB's default
      // limit of one worker per core minus the calling thread.
      impl_->parallelism.emplace(tbb::global_control::max_allowed_parallelism,
                                 static_cast<std::size_t>(threads) + 1);
      impl_->arena.emplace(threads, 0);
    }
  }
  for (auto& c : impl_->cells) c->actor->start();
  impl_->started = true;
  if (!impl_->options.manual) {
    // Messages queued before start. Only actors that have some: a drain of an empty inbox would
    // hold the strand for a moment, and a message imported then could not run at once.
    for (auto& c : impl_->cells) {
      bool queued = false;
      {
        std::lock_guard lock(c->mutex);
        queued = !c->queue.empty();
      }
      if (queued) impl_->schedule(*c);
    }
  }
}

bool Runtime::step() {
  return impl_->stepOne();
}

std::size_t Runtime::runUntilIdle() {
  std::size_t n = 0;
  while (impl_->stepOne()) ++n;
  return n;
}

bool Runtime::fireDueTimers(Nanos limit) {
  auto& rt = *impl_;
  Nanos due = std::numeric_limits<Nanos>::max();
  {
    std::lock_guard lock(rt.timers_mutex);
    for (const auto& t : rt.timers) due = std::min(due, t.next);
  }
  if (due > limit) {
    if (rt.clock.kind() == ClockKind::kSimulated) rt.clock.advanceTo(limit);
    return false;
  }
  if (rt.clock.kind() == ClockKind::kSimulated) rt.clock.advanceTo(due);
  std::vector<std::size_t> fire;
  {
    std::lock_guard lock(rt.timers_mutex);
    for (std::size_t i = 0; i < rt.timers.size(); ++i) {
      auto& t = rt.timers[i];
      if (t.next == due) {
        fire.push_back(i);
        t.next = t.period == 0 ? detail::Timer::kIdle : t.next + t.period;
      }
    }
  }
  for (auto i : fire) rt.queueTimer(i);
  return true;
}

void Runtime::Impl::stopActors(const std::vector<std::uint32_t>& order) {
  for (auto i : order) {
    if (options.manual) {
      while (stepOne()) {
      }
    } else {
      waitIdle();
    }
    try {
      cells[i]->actor->stop();
    } catch (const std::exception& e) {
      // One actor failing to flush must not stop the others from writing their outputs.
      std::fprintf(stderr, "error: actor '%s' failed in stop(): %s\n", cells[i]->name.c_str(),
                   e.what());
      std::lock_guard lock(stop_reason_mutex);
      stop_reason += (stop_reason.empty() ? "" : "; ") +
                     ("actor '" + cells[i]->name + "' failed in stop(): " + e.what());
    }
  }
  if (options.manual) {
    while (stepOne()) {
    }
  } else {
    waitIdle();
  }
}

void Runtime::stop() {
  if (!impl_->started || impl_->stopped) return;
  impl_->stopped = true;
  impl_->stopActors(impl_->stopOrder());
  impl_->final_report = impl_->makeReport();
  impl_->pool.reset();
  impl_->arena.reset();
  impl_->parallelism.reset();
}

RunReport Runtime::report() const {
  return impl_->stopped ? impl_->final_report : impl_->makeReport();
}

namespace {
std::atomic<Runtime*> g_signal_target{nullptr};
std::atomic<int> g_signal_count{0};
extern "C" void onStopSignal(int) {
  if (g_signal_count.fetch_add(1) >= 1) {
    static const char msg[] = "\nsecond interrupt: exiting without writing outputs\n";
    (void)!write(2, msg, sizeof(msg) - 1);
    _exit(130);
  }
  if (auto* rt = g_signal_target.load()) rt->requestStop();
}

void printProgress(const Runtime::Impl& rt, bool final_line) {
  double fraction = 0;
  int finite = 0;
  for (const auto& c : rt.cells) {
    if (!c->finite) continue;
    fraction += c->progress.load();
    ++finite;
  }
  const double wall = nanosToSeconds(steadyNow() - rt.start_wall);
  const double sim = nanosToSeconds(rt.clock.now() - rt.start_sim);
  std::ostringstream s;
  s << std::fixed << std::setprecision(1);
  if (finite > 0)
    s << "[progress] " << std::setw(5) << 100.0 * fraction / finite << "% | ";
  else
    s << "[running] ";
  s << "data " << sim << " s | wall " << wall << " s";
  if (rt.clock.kind() == ClockKind::kSimulated && wall > 0)
    s << " | " << sim / wall << "x real time";
  const bool tty = isatty(2);
  std::fprintf(stderr, tty ? "\r%s\033[K%s" : "%s%s", s.str().c_str(),
               (final_line || !tty) ? "\n" : "");
  std::fflush(stderr);
}
}  // namespace

void Runtime::requestStop() {
  // Async-signal-safe: only an atomic store (the reason is filled in by run()).
  impl_->stop_requested.store(true);
}

void Runtime::installSignalHandlers() {
  g_signal_target.store(this);
  g_signal_count.store(0);
  struct sigaction sa {};
  sa.sa_handler = onStopSignal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

RunReport Runtime::run() {
  auto& rt = *impl_;
  if (rt.options.manual) throw std::logic_error("Runtime::run in manual mode; use step()");
  start();
  const bool sim = rt.clock.kind() == ClockKind::kSimulated;
  const Nanos limit = rt.options.max_sim_duration > 0 ? rt.start_sim + rt.options.max_sim_duration
                                                      : std::numeric_limits<Nanos>::max();
  Nanos last_progress = steadyNow();
  const Nanos progress_every = isatty(2) ? kNanosPerSecond / 2 : 5 * kNanosPerSecond;
  std::string end_reason;

  auto allSourcesDone = [&] {
    return rt.finite_sources.load() > 0 && rt.finished_sources.load() >= rt.finite_sources.load();
  };

  auto* coordinator = rt.options.coordinator;
  auto localState = [&] {
    RunCoordinator::LocalState s;
    s.next_due = std::numeric_limits<Nanos>::max();
    {
      std::lock_guard lock(rt.timers_mutex);
      for (const auto& t : rt.timers) s.next_due = std::min(s.next_due, t.next);
    }
    s.finite_sources = rt.finite_sources.load();
    s.finished_sources = rt.finished_sources.load();
    return s;
  };

  while (true) {
    if (sim) rt.waitIdle();
    if (rt.stop_requested.load()) break;
    if (coordinator != nullptr) {
      // The deployment decides when time moves and when the run ends.
      const auto decision =
          sim ? coordinator->idle(
                    localState(),
                    [&] { return rt.pending.load() != 0 || rt.stop_requested.load(); })
              : coordinator->poll(localState(), [&] { return rt.pending.load() != 0; });
      using V = RunCoordinator::Verdict;
      if (decision.verdict == V::kFinish) {
        end_reason = decision.reason;
        if (sim && decision.time > rt.clock.now()) rt.clock.advanceTo(decision.time);
        break;
      }
      if (decision.verdict == V::kStop) {
        rt.requestStop(decision.reason);
        break;
      }
      if (decision.verdict == V::kAdvance) {
        fireDueTimers(decision.time);
        continue;
      }
      if (sim) continue;  // kWork: messages arrived
    } else if (allSourcesDone() && rt.pending.load() == 0) {
      end_reason = "all inputs finished";
      break;
    }
    if (rt.options.show_progress && steadyNow() - last_progress >= progress_every) {
      printProgress(rt, false);
      last_progress = steadyNow();
    }
    Nanos due = std::numeric_limits<Nanos>::max();
    {
      std::lock_guard lock(rt.timers_mutex);
      for (const auto& t : rt.timers) due = std::min(due, t.next);
    }
    if (sim) {
      if (due == std::numeric_limits<Nanos>::max()) {
        end_reason = "nothing left to do (no timers, all mailboxes empty)";
        break;
      }
      if (due > limit) {
        rt.clock.advanceTo(limit);
        end_reason = "reached max_duration_s";
        break;
      }
      if (rt.options.sim_rate > 0) {
        const auto wall_target =
            rt.start_wall +
            static_cast<Nanos>(static_cast<double>(due - rt.start_sim) / rt.options.sim_rate);
        while (steadyNow() < wall_target && !rt.stop_requested.load()) {
          std::this_thread::sleep_for(
              std::chrono::nanoseconds(std::min<Nanos>(wall_target - steadyNow(), 20'000'000)));
        }
      }
      fireDueTimers(due);
    } else {
      const Nanos now = rt.clock.now();
      if (due > now) {
        std::unique_lock lock(rt.idle_mutex);
        rt.idle_cv.wait_for(lock, std::chrono::nanoseconds(std::min<Nanos>(due - now, 20'000'000)));
        continue;
      }
      std::vector<std::size_t> fire;
      {
        std::lock_guard lock(rt.timers_mutex);
        for (std::size_t i = 0; i < rt.timers.size(); ++i) {
          auto& t = rt.timers[i];
          if (t.next > now) continue;
          fire.push_back(i);
          if (t.period == 0) {
            t.next = detail::Timer::kIdle;
            continue;
          }
          t.next += t.period;
          if (t.next <= now) {  // fell behind by more than a period: skip, don't burst
            ++t.overruns;
            t.next = now + t.period;
          }
        }
      }
      for (auto i : fire) rt.queueTimer(i);
    }
  }
  if (rt.stop_requested.load()) {
    std::lock_guard lock(rt.stop_reason_mutex);
    if (rt.stop_reason.empty()) rt.stop_reason = "interrupted (SIGINT/SIGTERM)";
  } else {
    rt.stop_reason = end_reason;
  }
  if (rt.options.show_progress) printProgress(rt, true);
  // Stop sources first; everything they queued is handled before downstream actors stop.
  rt.stopped = true;
  if (coordinator == nullptr) {
    rt.stopActors(rt.stopOrder());
  } else {
    // The deployment interleaves the processes' actors in one stop order: a process may stop
    // some actors, then others of another process, then more of its own.
    for (;;) {
      const auto names = coordinator->awaitStopTurn([&] { return rt.pending.load() != 0; });
      if (names.empty()) break;
      std::vector<std::uint32_t> order;
      for (const auto& name : names) {
        for (std::uint32_t i = 0; i < rt.cells.size(); ++i) {
          if (rt.cells[i]->name == name) order.push_back(i);
        }
      }
      rt.stopActors(order);
      coordinator->stopped();
    }
  }
  rt.final_report = rt.makeReport();
  rt.pool.reset();
  rt.arena.reset();
  rt.parallelism.reset();
  g_signal_target.store(nullptr);
  return rt.final_report;
}

const Clock& Runtime::clock() const {
  return impl_->clock;
}

std::string Runtime::globalTopic(const std::string& actor, const std::string& local) const {
  for (const auto& c : impl_->cells) {
    if (c->name != actor) continue;
    auto it = c->remap.find(local);
    return it == c->remap.end() ? local : it->second;
  }
  throw std::invalid_argument("no actor named '" + actor + "'");
}

std::vector<std::string> Runtime::subscriptionsOf(const std::string& actor) const {
  for (const auto& c : impl_->cells) {
    if (c->name != actor) continue;
    std::vector<std::string> out;
    for (const auto& s : c->slots) out.push_back(s.topic);
    return out;
  }
  throw std::invalid_argument("no actor named '" + actor + "'");
}

std::vector<std::string> Runtime::stopOrder() const {
  std::vector<std::string> out;
  for (auto i : impl_->stopOrder()) out.push_back(impl_->cells[i]->name);
  return out;
}

std::vector<std::string> Runtime::publicationsOf(const std::string& actor) const {
  for (const auto& c : impl_->cells) {
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
  for (const auto& c : impl_->cells) {
    if (c->name != actor) continue;
    for (const auto& s : c->slots) {
      if (s.topic == topic) return s.policy;
    }
  }
  throw std::invalid_argument("actor '" + actor + "' does not subscribe to '" + topic + "'");
}

std::string RunReport::table() const {
  std::ostringstream s;
  s << std::left << std::setw(22) << "actor" << std::right << std::setw(10) << "in" << std::setw(10)
    << "out" << std::setw(9) << "timers" << std::setw(8) << "drops" << std::setw(7) << "maxq"
    << std::setw(11) << "p50 us" << std::setw(11) << "p99 us" << std::setw(10) << "busy s"
    << "\n";
  s << std::fixed;
  for (const auto& a : actors) {
    s << std::left << std::setw(22) << a.name << std::right << std::setw(10) << a.messages_in
      << std::setw(10) << a.messages_out << std::setw(9) << a.timer_calls << std::setw(8) << a.drops
      << std::setw(7) << a.max_queue_depth << std::setprecision(1) << std::setw(11)
      << a.handler_p50_us << std::setw(11) << a.handler_p99_us << std::setprecision(2)
      << std::setw(10) << a.handler_total_s << "\n";
  }
  for (const auto& a : actors) {
    if (a.malformed > 0) s << a.name << ": " << a.malformed << " malformed messages dropped\n";
  }
  return s.str();
}

}  // namespace tessera
