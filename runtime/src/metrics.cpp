// Metrics: the handler-time histogram, the run report assembled from every actor's counters
// (summary.json and the exit table), and the table's text.
#include "runtime_impl.hpp"

#include <tessera/runtime/process_stats.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <iomanip>
#include <sstream>

namespace tessera {
namespace detail {

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

}  // namespace detail

RunReport Runtime::Impl::makeReport() const {
  RunReport r;
  r.wall_s = nanosToSeconds(steadyNow() - start_wall);
  r.cpu_s = processCpuSeconds() - start_cpu;
  r.sim_duration_s = nanosToSeconds(clock.now() - start_sim);
  r.peak_rss_mb = peakRssMegabytes();
  r.interrupted = stop_requested.load();
  r.stop_reason = stop_reason;
  for (const auto& c : actors) {
    ActorReport a;
    a.name = c->name;
    a.messages_in = c->messages_in;
    a.messages_out = c->messages_out;
    a.timer_calls = c->timer_calls;
    a.malformed = c->malformed;
    for (const auto& s : c->subscriptions) {
      a.drops += s.drops;
      a.subscriptions.push_back(
          {s.topic, s.policy.kind == MailboxPolicy::Kind::kReliable, s.handled, s.drops});
    }
    a.max_queue_depth = c->max_depth;
    a.queue_wait_p50_us = c->queue_wait.percentileMicros(0.50);
    a.queue_wait_p99_us = c->queue_wait.percentileMicros(0.99);
    a.handler_p50_us = c->handler_time.percentileMicros(0.50);
    a.handler_p99_us = c->handler_time.percentileMicros(0.99);
    a.handler_total_s = c->handler_time.totalSeconds();
    c->instance->summarize(a.summary);
    r.actors.push_back(std::move(a));
  }
  for (const auto& [name, t] : topics) {
    const auto n = t->published.load(std::memory_order_relaxed);
    if (n > 0) r.topics.push_back({name, n, t->published_bytes.load(std::memory_order_relaxed)});
  }
  return r;
}

RunReport Runtime::report() const {
  return impl_->stopped ? impl_->final_report : impl_->makeReport();
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
