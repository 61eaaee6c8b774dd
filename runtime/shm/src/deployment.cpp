#include <tessera/shm/deployment.hpp>

#include <tessera/runtime/registry.hpp>

#include <fcntl.h>
#include <linux/futex.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <limits>
#include <set>
#include <stdexcept>
#include <thread>

namespace tessera {

int DeploymentPlan::indexOf(const std::string& process) const {
  for (std::size_t i = 0; i < processes.size(); ++i) {
    if (processes[i] == process) return static_cast<int>(i);
  }
  return -1;
}

std::size_t messageBound(const MessageType& type) {
  const std::string name = type.name;
  // Families with large arrays: grids and submaps (a 100 m x 100 m map at 5 cm is 4 MB), images
  // and depth frames, point sets. Everything else (scans, poses, odometry, constraints) is small.
  if (name == "OccupancyGrid" || name == "Submap") return std::size_t{16} << 20;
  if (name.find("Image") != std::string::npos || name.find("Rgbd") != std::string::npos ||
      name.find("Frame") != std::string::npos) {
    return std::size_t{8} << 20;
  }
  if (name == "Blob") return std::size_t{4} << 20;
  return std::size_t{256} << 10;
}

DeploymentPlan planDeployment(const Profile& full_profile, const std::string& host) {
  // The actors of other hosts that cannot be built here stay out of the wiring.
  Profile profile = full_profile;
  std::map<std::string, std::string> unchecked;
  if (!host.empty()) {
    std::erase_if(profile.actors, [&](const ActorSpec& a) {
      if (a.process == host) return false;
      try {
        (void)ActorRegistry::instance().create(a.type, a.params);
        return false;
      } catch (const std::exception& e) {
        unchecked[a.name] = e.what();
        return true;
      }
    });
  }
  DeploymentPlan plan;
  plan.unchecked = std::move(unchecked);
  std::vector<std::string> order;  // first appearance in the profile
  for (const auto& a : full_profile.actors) {
    if (std::find(order.begin(), order.end(), a.process) == order.end()) order.push_back(a.process);
    plan.actors[a.process].push_back(a.name);
  }
  if (order.size() > static_cast<std::size_t>(kMaxDeploymentProcesses)) {
    throw ConfigError(profile.path + ": " + std::to_string(order.size()) +
                      " processes; a deployment has at most " +
                      std::to_string(kMaxDeploymentProcesses));
  }
  for (const auto& r : profile.restart) {
    if (!plan.actors.count(r)) {
      throw ConfigError(profile.path + ": restart names process '" + r +
                        "', but no actor runs in it");
    }
  }
  // The wiring, from every actor configured once in a runtime that never starts.
  RuntimeOptions options;
  options.manual = true;
  auto rt = plan.unchecked.empty() ? buildRuntime(profile, options)
                                   : buildWiringRuntime(profile, options);
  struct Wiring {
    MessageType type;
    std::set<std::string> publishers;
    std::map<std::string, MailboxPolicy> subscribers;  // process -> strongest policy
  };
  std::map<std::string, Wiring> topics;
  for (const auto& a : profile.actors) {
    for (const auto& t : rt->publicationsOf(a.name)) {
      topics[t].type = rt->topicType(t);
      topics[t].publishers.insert(a.process);
    }
    for (const auto& t : rt->subscriptionsOf(a.name)) {
      auto& w = topics[t];
      w.type = rt->topicType(t);
      const auto policy = rt->subscriptionPolicy(a.name, t);
      auto [it, fresh] = w.subscribers.emplace(a.process, policy);
      if (!fresh) {
        auto& p = it->second;
        if (policy.kind == MailboxPolicy::Kind::kReliable) p.kind = policy.kind;
        p.capacity = std::max(p.capacity, policy.capacity);
      }
    }
  }

  // Stop order: a process stops after every process that publishes to it (cycles broken by
  // profile order), as actors do inside one process.
  std::map<std::string, std::set<std::string>> upstream;
  for (const auto& [name, w] : topics) {
    for (const auto& [sub, policy] : w.subscribers) {
      for (const auto& pub : w.publishers) {
        if (pub != sub) upstream[sub].insert(pub);
      }
    }
  }
  std::vector<std::string> remaining = order;
  while (!remaining.empty()) {
    auto pick = remaining.begin();
    for (auto it = remaining.begin(); it != remaining.end(); ++it) {
      bool ready = true;
      for (const auto& u : upstream[*it]) {
        ready = ready &&
                std::find(plan.processes.begin(), plan.processes.end(), u) != plan.processes.end();
      }
      if (ready) {
        pick = it;
        break;
      }
    }
    plan.processes.push_back(*pick);
    remaining.erase(pick);
  }

  std::map<std::string, int> process_of;
  for (const auto& a : profile.actors) process_of[a.name] = plan.indexOf(a.process);
  for (const auto& actor : rt->stopOrder()) {
    const int p = process_of.at(actor);
    if (plan.stop_stages.empty() || plan.stop_stages.back().process != p) {
      plan.stop_stages.push_back({p, {}});
    }
    plan.stop_stages.back().actors.push_back(actor);
  }

  const auto listed = [](const std::vector<std::string>& list, const std::string& topic) {
    return std::find(list.begin(), list.end(), topic) != list.end();
  };
  for (const auto& [name, w] : topics) {
    std::set<std::string> involved(w.publishers.begin(), w.publishers.end());
    for (const auto& [sub, policy] : w.subscribers) involved.insert(sub);
    // A program outside the deployment (profile `external:`) is one more party to the topic.
    const bool outside_pub = listed(profile.external_inputs, name);
    const bool outside_sub = listed(profile.external_outputs, name);
    const std::size_t parties = involved.size() + (outside_pub ? 1 : 0) + (outside_sub ? 1 : 0);
    if (parties < 2 || (w.publishers.empty() && !outside_pub) ||
        (w.subscribers.empty() && !outside_sub)) {
      continue;
    }
    bool any_reliable = false, any_loop = false;
    std::uint32_t alive = 0;
    for (const auto& [sub, policy] : w.subscribers) {
      any_reliable = any_reliable || policy.kind == MailboxPolicy::Kind::kReliable;
      any_loop = any_loop || w.publishers.count(sub) > 0;
      alive += static_cast<std::uint32_t>(std::min<std::size_t>(policy.capacity, 256)) + 2;
    }
    alive += 8 * static_cast<std::uint32_t>(w.publishers.size());
    if (outside_pub) alive += 8;   // an outside publisher's loans
    if (outside_sub) alive += 18;  // an outside reader's queue and what it holds
    plan.demands.push_back({messageBound(w.type) + kShmChunkOverhead, alive});
    for (const auto& process : involved) {
      ShmTopic t;
      t.name = name;
      t.type = w.type;
      t.exported = w.publishers.count(process) > 0;
      auto sub = w.subscribers.find(process);
      t.imported = sub != w.subscribers.end();
      if (t.imported) t.import_policy = sub->second;
      t.importing_processes = static_cast<std::uint32_t>(w.subscribers.size());
      t.publishing_processes = static_cast<std::uint32_t>(w.publishers.size());
      t.any_reliable = any_reliable || any_loop;
      plan.topics[process].push_back(t);
    }
    for (const auto& pub : w.publishers) {
      for (const auto& [sub, policy] : w.subscribers) {
        const int from = plan.indexOf(pub), to = plan.indexOf(sub);
        if (from < 0 || to < 0) continue;
        plan.routes.push_back({name, from, to, policy.kind == MailboxPolicy::Kind::kReliable});
      }
    }
  }
  return plan;
}

// ------------------------------------------------------------------ control block

namespace {
/// What a control block's shared memory holds: the block, then the delivery ledger.
struct ControlMemory {
  SyncBlock block;
  DeliveryLedger ledger;
};
}  // namespace

RouteLedger routeLedger(const DeploymentPlan& plan, DeliveryLedger& ledger) {
  // The routes are copied into the lookups: a transport may outlive the caller's plan.
  std::vector<DeliveryRoute> routes(
      plan.routes.begin(),
      plan.routes.begin() +
          std::min<std::ptrdiff_t>(static_cast<std::ptrdiff_t>(plan.routes.size()),
                                   kMaxDeliveryRoutes));
  RouteLedger l;
  l.outgoing = [routes, &ledger](const std::string& topic, std::uint32_t from) {
    std::vector<RouteCounters*> out;
    for (std::size_t i = 0; i < routes.size(); ++i) {
      if (routes[i].topic == topic && routes[i].from == static_cast<int>(from)) {
        out.push_back(&ledger.routes[i]);
      }
    }
    return out;
  };
  l.incoming = [routes, &ledger](const std::string& topic, std::uint32_t from,
                                 std::uint32_t to) -> RouteCounters* {
    for (std::size_t i = 0; i < routes.size(); ++i) {
      if (routes[i].topic == topic && routes[i].from == static_cast<int>(from) &&
          routes[i].to == static_cast<int>(to)) {
        return &ledger.routes[i];
      }
    }
    return nullptr;
  };
  return l;
}

std::vector<RouteDelivery> readDelivery(const DeploymentPlan& plan, const DeliveryLedger& ledger,
                                        const std::vector<bool>& died) {
  std::vector<RouteDelivery> out;
  const auto dead = [&](int p) {
    return p >= 0 && static_cast<std::size_t>(p) < died.size() && died[p];
  };
  for (std::size_t i = 0; i < plan.routes.size() && i < kMaxDeliveryRoutes; ++i) {
    RouteDelivery d;
    d.route = plan.routes[i];
    d.sent = ledger.routes[i].sent.load();
    d.received = ledger.routes[i].received.load();
    const std::uint64_t gaps = ledger.routes[i].gaps.load();
    // A sender killed between publishing and counting leaves one more received than sent.
    const std::uint64_t missing = d.sent > d.received ? d.sent - d.received : 0;
    if (dead(d.route.from)) d.dead.push_back(plan.processes[d.route.from]);
    if (dead(d.route.to) && d.route.to != d.route.from)
      d.dead.push_back(plan.processes[d.route.to]);
    if (d.dead.empty()) {
      d.lost_live = std::max(missing, gaps);
    } else {
      d.lost_live = std::min(gaps, missing);
      d.lost_with_dead = missing - d.lost_live;
    }
    out.push_back(std::move(d));
  }
  return out;
}

SyncMemory::SyncMemory(const std::string& name, bool create) : name_(name), owner_(create) {
  const int fd = create ? ::shm_open(name.c_str(), O_CREAT | O_EXCL | O_RDWR, 0600)
                        : ::shm_open(name.c_str(), O_RDWR, 0600);
  if (fd < 0) {
    throw std::runtime_error("shared memory '" + name + "': " + std::strerror(errno));
  }
  if (create && ::ftruncate(fd, sizeof(ControlMemory)) != 0) {
    const int e = errno;
    ::close(fd);
    ::shm_unlink(name.c_str());
    throw std::runtime_error("shared memory '" + name + "': " + std::strerror(e));
  }
  void* p = ::mmap(nullptr, sizeof(ControlMemory), PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  ::close(fd);
  if (p == MAP_FAILED) {
    if (create) ::shm_unlink(name.c_str());
    throw std::runtime_error("shared memory '" + name + "': mmap failed");
  }
  // Zero-filled by ftruncate: every atomic starts at 0.
  block_ = &static_cast<ControlMemory*>(p)->block;
  ledger_ = &static_cast<ControlMemory*>(p)->ledger;
}

SyncMemory::~SyncMemory() {
  if (block_ != nullptr) ::munmap(block_, sizeof(ControlMemory));
  if (owner_) ::shm_unlink(name_.c_str());
}

// ------------------------------------------------------------------ doorbells

namespace {
long futex(std::atomic<std::uint32_t>& word, int op, std::uint32_t value, const timespec* timeout) {
  static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t));
  // Not FUTEX_PRIVATE_FLAG: the word is in memory shared between processes.
  return ::syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(&word), op, value, timeout, nullptr,
                   0);
}
}  // namespace

void ringBell(std::atomic<std::uint32_t>& bell, const std::atomic<std::uint32_t>& waiting) {
  bell.fetch_add(1);
  if (waiting.load() != 0) futex(bell, FUTEX_WAKE, INT32_MAX, nullptr);
}

void waitBell(std::atomic<std::uint32_t>& bell, std::atomic<std::uint32_t>& waiting,
              std::uint32_t seen, std::chrono::microseconds timeout) {
  const timespec t{static_cast<time_t>(timeout.count() / 1000000),
                   static_cast<long>(timeout.count() % 1000000) * 1000};
  waiting.fetch_add(1);
  // Returns at once when the bell rang after `seen` was read (the value differs).
  futex(bell, FUTEX_WAIT, seen, &t);
  waiting.fetch_sub(1);
}

// ------------------------------------------------------------------ worker side

namespace {
/// Waits with growing pauses: a hand-off within microseconds when the peer is quick, without
/// burning a core when it is not.
class Backoff {
 public:
  void pause() {
    // On a 2-core machine the peer needs the core: yield a little, then sleep (the process sets a
    // small timer slack, so short sleeps stay short).
    if (++n_ < 16) {
      std::this_thread::yield();
    } else {
      std::this_thread::sleep_for(std::chrono::microseconds(n_ < 2000 ? 10 : 200));
    }
  }

 private:
  int n_ = 0;
};
}  // namespace

WorkerCoordinator::WorkerCoordinator(SyncBlock& block, int index, std::vector<StopStage> stages)
    : block_(block), index_(index), launcher_(::getppid()), stages_(std::move(stages)) {
  auto& s = slot();
  s.idle = 0;
  s.stopped = 0;
  s.wants_stop = 0;
  s.ready = 0;
  s.pid = ::getpid();
  s.sent = 0;
  s.received = 0;
  s.gen.fetch_add(1);
  last_grant_ = block_.grant_seq.load();
}

bool WorkerCoordinator::readyAndWait() {
  slot().ready = 1;
  changed();
  Backoff b;
  while (block_.go.load() == 0) {
    if (ending()) return false;
    b.pause();
  }
  return block_.command.load() == RunCommand::kRun;
}

bool WorkerCoordinator::ending() {
  return block_.command.load() != RunCommand::kRun || orphaned();
}

bool WorkerCoordinator::orphaned() {
  // The launcher owns RouDi: when it is gone nobody moves time or ends the run.
  if (!orphaned_ && ++checks_ % 64 == 0 && ::getppid() != launcher_) {
    if (on_orphaned_) on_orphaned_();
    orphaned_ = true;
  }
  return orphaned_;
}

RunCoordinator::Decision WorkerCoordinator::ended() const {
  Decision d;
  if (orphaned_) {
    d.verdict = Verdict::kStop;
    d.reason = "the launcher (and its RouDi) died";
    return d;
  }
  d.verdict = block_.command.load() == RunCommand::kFinish ? Verdict::kFinish : Verdict::kStop;
  d.time = block_.end_time.load();
  d.reason = std::string(block_.reason, strnlen(block_.reason, sizeof(block_.reason)));
  return d;
}

void WorkerCoordinator::publishIdle(bool idle, std::uint64_t received) {
  // `received` was read before the caller found the process idle: every message it counts has
  // been handled, so the launcher may take "idle with these receipts" at face value.
  auto& s = slot();
  if (idle == (s.idle.load() == 1) && (!idle || s.recv_at_idle.load() == received)) return;
  if (idle) s.recv_at_idle = received;
  s.gen.fetch_add(1);
  s.idle = idle ? 1 : 0;
  changed();
}

RunCoordinator::Decision WorkerCoordinator::idle(const LocalState& state,
                                                 const std::function<bool()>& busy) {
  auto& s = slot();
  s.next_due = state.next_due;
  s.finite = state.finite_sources;
  s.finished = state.finished_sources;
  s.grant_seen = last_grant_;
  s.gen.fetch_add(1);  // new timer/source figures
  changed();
  for (int round = 0;; ++round) {
    // Read before looking, so that a ring (a grant, a message) after the look ends the wait.
    const std::uint32_t bell = s.bell.load();
    const auto received = s.received.load();
    if (busy()) {
      publishIdle(false, received);
      return {Verdict::kWork, 0, {}};
    }
    publishIdle(true, received);
    if (block_.command.load() != RunCommand::kRun || orphaned()) return ended();
    const auto g = block_.grant_seq.load();
    if (g != last_grant_) {
      last_grant_ = g;
      publishIdle(false, received);
      return {Verdict::kAdvance, block_.grant_time.load(), {}};
    }
    // The launcher usually answers within microseconds: a few yields, then sleep until a ring.
    if (round < 4) {
      std::this_thread::yield();
    } else {
      waitBell(s.bell, s.waiting, bell, std::chrono::milliseconds(2));
    }
  }
}

RunCoordinator::Decision WorkerCoordinator::poll(const LocalState& state,
                                                 const std::function<bool()>& busy) {
  auto& s = slot();
  s.next_due = state.next_due;
  s.finite = state.finite_sources;
  s.finished = state.finished_sources;
  const auto received = s.received.load();
  publishIdle(!busy(), received);
  if (block_.command.load() != RunCommand::kRun || orphaned()) return ended();
  return {Verdict::kWork, 0, {}};
}

std::vector<std::string> WorkerCoordinator::awaitStopTurn(const std::function<bool()>& busy) {
  auto& s = slot();
  if (block_.command.load() == RunCommand::kRun) {
    s.wants_stop = 1;  // a local stop (signal, fatal error)
    changed();
  }
  while (next_stage_ < stages_.size() && stages_[next_stage_].process != index_) ++next_stage_;
  // After its last stage the process still handles what later stages send it (a cycle of
  // actors), until every stage is done and the launcher lets it leave.
  const std::size_t turn = std::min(next_stage_, stages_.size());  // the last: leave
  Backoff b;
  while (block_.command.load() == RunCommand::kRun || block_.stop_turn.load() <= turn) {
    if (orphaned()) {
      // Nobody grants turns any more: stop what is left here at once (outputs get written).
      std::vector<std::string> rest;
      for (; next_stage_ < stages_.size(); ++next_stage_) {
        if (stages_[next_stage_].process != index_) continue;
        rest.insert(rest.end(), stages_[next_stage_].actors.begin(),
                    stages_[next_stage_].actors.end());
      }
      s.stopped = 1;
      changed();
      return rest;
    }
    const auto received = s.received.load();
    publishIdle(!busy(), received);
    b.pause();
  }
  if (next_stage_ >= stages_.size()) {
    s.stopped = 1;
    changed();
    return {};
  }
  return stages_[next_stage_++].actors;
}

void WorkerCoordinator::stopped() {
  publishIdle(true, slot().received.load());  // stopActors() drained everything
  block_.stages_done = next_stage_;
  changed();
}

// ------------------------------------------------------------------ the launcher's clock

DeploymentClock::DeploymentClock(SyncBlock& block, int processes, std::vector<int> stage_owners,
                                 bool sim, double sim_rate, Nanos limit)
    : block_(block),
      n_(processes),
      stage_owners_(std::move(stage_owners)),
      sim_(sim),
      rate_(sim_rate),
      limit_(limit) {}

void DeploymentClock::markGone(int index) {
  std::lock_guard lock(mutex_);
  gone_[index] = true;
  unbalanced_ = true;
}

void DeploymentClock::markRestarted(int index) {
  std::lock_guard lock(mutex_);
  auto& s = block_.slots[index];
  s.ready = 0;
  s.idle = 0;
  s.stopped = 0;
  s.wants_stop = 0;
  s.waiting = 0;  // the old one may have died asleep
  s.gen.fetch_add(1);
  gone_[index] = false;
}

void DeploymentClock::requestStop(const std::string& reason) {
  std::lock_guard lock(mutex_);
  if (block_.command.load() == RunCommand::kRun) issue(RunCommand::kStop, reason, 0);
}

std::vector<int> DeploymentClock::holdingUpStop() {
  std::lock_guard lock(mutex_);
  std::vector<int> out;
  const auto turn = block_.stop_turn.load();
  if (block_.command.load() == RunCommand::kRun || turn > stage_owners_.size()) return out;
  if (turn > 0) {
    const int owner = stage_owners_[turn - 1];
    if (!gone_[owner] && block_.stages_done.load() < turn) return {owner};
  }
  for (int i = 0; i < n_; ++i) {
    const auto& s = block_.slots[i];
    if (!gone_[i] && (s.idle.load() != 1 || s.recv_at_idle.load() != s.received.load())) {
      out.push_back(i);
    }
  }
  return out;
}

std::string DeploymentClock::reason() const {
  return std::string(block_.reason, strnlen(block_.reason, sizeof(block_.reason)));
}

void DeploymentClock::step() {
  std::lock_guard lock(mutex_);
  if (block_.go.load() == 0) {
    for (int i = 0; i < n_; ++i) {
      if (!gone_[i] && block_.slots[i].ready.load() == 0) return;
    }
    start_wall_ = steadyNow();
    block_.go = 1;
    return;
  }
  if (block_.command.load() == RunCommand::kRun) {
    for (int i = 0; i < n_; ++i) {
      if (!gone_[i] && block_.slots[i].wants_stop.load() != 0) {
        issue(RunCommand::kStop, "process stopped by itself (signal or actor error)", 0);
        return;
      }
    }
    if (!quiescent(true)) return;
    std::int64_t finite = 0, finished = 0;
    Nanos due = std::numeric_limits<Nanos>::max();
    for (int i = 0; i < n_; ++i) {
      if (gone_[i]) continue;
      finite += block_.slots[i].finite.load();
      finished += block_.slots[i].finished.load();
      due = std::min<Nanos>(due, block_.slots[i].next_due.load());
    }
    if (finite > 0 && finished >= finite) {
      issue(RunCommand::kFinish, "all inputs finished", 0);
      return;
    }
    if (!sim_) return;
    if (due == std::numeric_limits<Nanos>::max()) {
      issue(RunCommand::kFinish, "nothing left to do (no timers, all mailboxes empty)", 0);
      return;
    }
    if (due > limit_) {
      issue(RunCommand::kFinish, "reached max_duration_s", limit_);
      return;
    }
    if (rate_ > 0) {
      if (first_due_ < 0) first_due_ = due;
      const Nanos target =
          start_wall_ + static_cast<Nanos>(static_cast<double>(due - first_due_) / rate_);
      if (steadyNow() < target) return;
    }
    block_.grant_time = due;
    block_.grant_seq.fetch_add(1);
    return;
  }
  // Stopping: stage k runs once stage k-1 is done and everything it sent was handled; one more
  // turn after the last stage lets every process leave.
  const auto turn = block_.stop_turn.load();
  const auto stages = static_cast<std::uint64_t>(stage_owners_.size());
  if (turn > stages) return;
  if (turn > 0 && !gone_[stage_owners_[turn - 1]] && block_.stages_done.load() < turn) return;
  if (!quiescent(false)) return;
  block_.stop_turn = turn + 1;
}

bool DeploymentClock::wave(bool running, std::vector<Snapshot>& out, std::uint64_t& sent,
                           std::uint64_t& recv) {
  out.assign(n_, {});
  sent = recv = 0;
  bool ok = true;
  for (int i = 0; i < n_; ++i) {
    auto& s = block_.slots[i];
    const auto g1 = s.gen.load();
    const bool idle = s.idle.load() == 1;
    const auto r = s.received.load();
    const auto sn = s.sent.load();
    const bool fresh = s.recv_at_idle.load() == r;
    const bool granted = !running || s.grant_seen.load() == block_.grant_seq.load();
    const auto g2 = s.gen.load();
    sent += sn;
    recv += r;
    out[i] = {g1, sn, r};
    if (gone_[i]) continue;
    ok = ok && idle && fresh && granted && g1 == g2;
  }
  return ok;
}

bool DeploymentClock::quiescent(bool running) {
  std::vector<Snapshot> a, b;
  std::uint64_t sa, ra, sb, rb;
  if (!wave(running, a, sa, ra)) return false;
  if (!wave(running, b, sb, rb)) return false;
  for (int i = 0; i < n_; ++i) {
    if (a[i].gen != b[i].gen || a[i].sent != b[i].sent || a[i].received != b[i].received)
      return false;
  }
  return unbalanced_ || sa == ra;
}

void DeploymentClock::issue(RunCommand command, const std::string& reason, Nanos end_time) {
  std::memset(block_.reason, 0, sizeof(block_.reason));
  std::memcpy(block_.reason, reason.data(), std::min(reason.size(), sizeof(block_.reason) - 1));
  block_.end_time = end_time;
  block_.stop_turn = 0;
  block_.stages_done = 0;
  block_.command = command;
}

}  // namespace tessera
