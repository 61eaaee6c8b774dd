// tessera bench runtime: one-hop latency and throughput of the in-process transport, measured
// against the floor of a bare condition-variable hand-off between two threads in the same run.
//
// Latency: an external thread publishes one message, stamps it just before publish(), and waits
// until every subscriber's handler has started; each handler records (start - stamp). A gap
// (default 1 ms) between building a message and publishing it lets the executor's threads go
// idle, so every hop includes a wake-up. It is 1 ms rather than 200 us because on this VM
// writing 1.5 MiB leaves the next cross-core wake-up slow for a few hundred microseconds
// (p50 ~72 us at --gap-us 200, ~6.4 us at 1000, for the same code); the gap keeps that
// hypervisor effect out of a transport figure.
// Throughput: the same publisher sends as fast as it can into reliable mailboxes while the
// subscribers stay busy; msgs_per_s counts published messages fully delivered per second.
// payload_copies counts deliveries whose bytes were not the published bytes.
#include "bench_commands.hpp"
#include "bench_util.hpp"

#include <tessera/messages/types.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/runtime.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstring>
#include <iomanip>
#include <iostream>
#include <mutex>
#include <thread>

namespace tessera::app {

namespace {

struct Options {
  int samples = 2000;
  int gap_us = 1000;
  double throughput_seconds = 1.0;
  bool json = false;
};

struct Row {
  std::string transport;
  std::size_t payload = 0;
  int subscribers = 0;
  double p50_us = 0, p99_us = 0, msgs_per_s = 0;
  std::uint64_t copies = 0;
  bool has_copies = false;
};

// Drops `storage` once no subscriber holds it any more.
void waitReleased(std::shared_ptr<const MessageStorage>& storage) {
  while (storage.use_count() > 1) std::this_thread::yield();
  storage.reset();
}

// ---- floor: bare condition variable hand-off ----
Row measureFloor(const Options& o) {
  std::mutex m;
  std::condition_variable cv;
  std::uint64_t posted = 0;
  Nanos stamp = 0;
  bool quit = false;
  std::atomic<int> acks{0};
  std::vector<double> lat;
  lat.reserve(static_cast<std::size_t>(o.samples));
  std::thread consumer([&] {
    std::uint64_t seen = 0;
    std::unique_lock lock(m);
    while (true) {
      cv.wait(lock, [&] { return posted != seen || quit; });
      if (quit) return;
      lat.push_back(static_cast<double>(steadyNow() - stamp) * 1e-3);
      seen = posted;
      acks.fetch_add(1, std::memory_order_release);
    }
  });
  for (int i = 0; i < o.samples; ++i) {
    {
      std::lock_guard lock(m);
      stamp = steadyNow();
      ++posted;
    }
    cv.notify_one();
    spinUntil(acks, i + 1);
    std::this_thread::sleep_for(std::chrono::microseconds(o.gap_us));
  }
  {
    std::lock_guard lock(m);
    quit = true;
  }
  cv.notify_one();
  consumer.join();
  Row r;
  r.transport = "floor";
  r.payload = 0;
  r.subscribers = 1;
  r.p50_us = percentile(lat, 0.5);
  r.p99_us = percentile(lat, 0.99);
  return r;
}

// ---- runtime ----
struct Shared {
  std::atomic<int> delivered{0};
  // Set by the publisher before publish(); the publish (a mutex hand-off) orders it before the
  // handlers' reads.
  const void* published_payload = nullptr;
  std::atomic<std::uint64_t> copies{0};
  std::mutex lat_mutex;
  std::vector<double> latencies;
  // A subscriber's reference to the latest sample, handed back to the publisher so that the
  // last reference (and so the release of the buffer) stays on the publisher's thread.
  std::shared_ptr<const MessageStorage> held;
  bool record = true;
};

class Probe : public Actor {
 public:
  explicit Probe(Shared& s) : s_(s) {}
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::Blob>(
        "bench", MailboxPolicy::reliable(1024), [this](const Message<msg::Blob>& m) {
          if (s_.record) {
            const Nanos now = steadyNow();
            const double us = static_cast<double>(now - m->getHeader().getStampNs()) * 1e-3;
            if (m->getPayload().begin() != s_.published_payload) ++s_.copies;
            std::lock_guard lock(s_.lat_mutex);
            s_.latencies.push_back(us);
            if (!s_.held) s_.held = m.storage();
          }
          s_.delivered.fetch_add(1, std::memory_order_release);
        });
  }

 private:
  Shared& s_;
};

Row measureRuntime(const Options& o, std::size_t payload, int subscribers,
                   RuntimeOptions::Executor executor = RuntimeOptions::Executor::kThreadPool) {
  Shared shared;
  RuntimeOptions ro;
  ro.executor = executor;
  ro.clock = ClockKind::kWall;
  ro.show_progress = false;
  Runtime rt(ro);
  auto pub = rt.externalPublisher<msg::Blob>("bench");
  for (int i = 0; i < subscribers; ++i)
    rt.add("probe" + std::to_string(i), std::make_unique<Probe>(shared));
  rt.configure();
  rt.start();

  auto build = [&] {
    auto loan = pub.loan(payload + 64);
    setHeader(loan->initHeader(), 0, "bench", pub.nextSeq());
    // Written like a real producer would (an image, a scan): every page of the payload is
    // touched, so the cost of fresh versus recycled memory shows in throughput.
    auto bytes = loan->initPayload(static_cast<unsigned>(payload));
    std::memset(bytes.begin(), 0x5a, bytes.size());
    shared.published_payload = bytes.begin();
    return loan;
  };

  // Latency: one message in flight at a time.
  const int samples = payload > (1u << 20) ? std::max(200, o.samples / 4) : o.samples;
  shared.latencies.reserve(static_cast<std::size_t>(samples * subscribers));
  int expected = 0;
  for (int i = 0; i < samples; ++i) {
    auto loan = build();
    expected += subscribers;
    // Then the gap, so every sample finds the subscribers idle and the machine quiet.
    std::this_thread::sleep_for(std::chrono::microseconds(o.gap_us));
    // Stamped last, right before publishing (sealing included), as an actor publishes: building
    // the payload is not latency. The fence waits until the payload's stores are done (large
    // memsets may use non-temporal stores that would otherwise drain inside the publish call
    // and count as delivery).
    std::atomic_thread_fence(std::memory_order_seq_cst);
    loan->getHeader().setStampNs(steadyNow());
    pub.publish(std::move(loan));
    spinUntil(shared.delivered, expected);
    // Taking a subscriber's reference back keeps the last one here, so the storage is released
    // (and a pooled buffer re-zeroed) on the publisher, as before the next sample is built.
    std::shared_ptr<const MessageStorage> held;
    {
      std::lock_guard lock(shared.lat_mutex);
      held = std::move(shared.held);
    }
    if (held) waitReleased(held);
  }
  Row r;
  r.transport = executor == RuntimeOptions::Executor::kThreadPool ? "inproc" : "inproc-tbb-arena";
  r.payload = payload;
  r.subscribers = subscribers;
  r.p50_us = percentile(shared.latencies, 0.5);
  r.p99_us = percentile(shared.latencies, 0.99);
  r.copies = shared.copies.load();
  r.has_copies = true;

  // Throughput: publish as fast as possible for about throughput_seconds.
  shared.record = false;
  const int base = shared.delivered.load();
  int sent = 0;
  const Nanos t0 = steadyNow();
  const Nanos budget = static_cast<Nanos>(o.throughput_seconds * 1e9);
  while (steadyNow() - t0 < budget) {
    for (int k = 0; k < 64; ++k) {
      auto loan = build();
      pub.publish(std::move(loan));
      ++sent;
    }
  }
  spinUntil(shared.delivered, base + sent * subscribers);
  const double elapsed = nanosToSeconds(steadyNow() - t0);
  r.msgs_per_s = sent / elapsed;
  rt.stop();
  return r;
}

}  // namespace

void addBenchRuntimeCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "runtime", "in-process messaging latency and throughput vs a condvar floor");
  auto o = std::make_shared<Options>();
  cmd->add_option("--samples", o->samples, "latency samples per configuration");
  cmd->add_option("--gap-us", o->gap_us, "idle gap between latency samples [us]");
  cmd->add_option("--throughput-seconds", o->throughput_seconds,
                  "duration of each throughput run [s]");
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    std::vector<Row> rows;
    rows.push_back(measureFloor(*o));
    for (std::size_t payload : {std::size_t{64}, std::size_t{64} << 10, std::size_t{1536} << 10}) {
      for (int subs : {1, 4}) rows.push_back(measureRuntime(*o, payload, subs));
    }
    // The alternative executor, for comparison: strands as tasks on a TBB task_arena.
    rows.push_back(measureRuntime(*o, 64, 1, RuntimeOptions::Executor::kTbbArena));
    const Row& floor = rows[0];
    auto find = [&](std::size_t payload, int subs) -> const Row& {
      for (const auto& r : rows)
        if (r.transport == "inproc" && r.payload == payload && r.subscribers == subs) return r;
      return rows[0];
    };
    const double ratio_floor = find(64, 1).p50_us / floor.p50_us;
    const double ratio_size = find(std::size_t{1536} << 10, 1).p50_us / find(64, 1).p50_us;
    const std::uint64_t fanout_copies =
        find(64, 4).copies + find(std::size_t{1536} << 10, 4).copies;
    const double rate64 = find(64, 1).msgs_per_s;

    if (o->json) {
      nlohmann::json j;
      j["machine"] = machineDescription();
      j["gap_us"] = o->gap_us;
      j["samples"] = o->samples;
      for (const auto& r : rows) {
        nlohmann::json x{{"transport", r.transport},
                         {"payload_bytes", r.payload},
                         {"subscribers", r.subscribers},
                         {"p50_us", r.p50_us},
                         {"p99_us", r.p99_us}};
        x["msgs_per_s"] =
            r.transport == "floor" ? nlohmann::json(nullptr) : nlohmann::json(r.msgs_per_s);
        x["payload_copies"] = r.has_copies ? nlohmann::json(r.copies) : nlohmann::json(nullptr);
        j["results"].push_back(x);
      }
      j["checks"] = {{"p50_over_floor_p50", ratio_floor},
                     {"p50_1536KiB_over_p50_64B", ratio_size},
                     {"fanout4_payload_copies", fanout_copies},
                     {"msgs_per_s_64B", rate64}};
      std::cout << j.dump(2) << "\n";
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << "latency: publish -> subscriber handler start, wake-up included (gap " << o->gap_us
              << " us between samples)\n\n";
    std::cout << std::left << std::setw(10) << "transport" << std::right << std::setw(12)
              << "payload B" << std::setw(6) << "subs" << std::setw(10) << "p50 us" << std::setw(10)
              << "p99 us" << std::setw(14) << "msgs/s" << std::setw(8) << "copies"
              << "\n";
    std::cout << std::fixed;
    for (const auto& r : rows) {
      std::cout << std::left << std::setw(10) << r.transport << std::right << std::setw(12)
                << r.payload << std::setw(6) << r.subscribers << std::setprecision(2)
                << std::setw(10) << r.p50_us << std::setw(10) << r.p99_us << std::setprecision(0)
                << std::setw(14) << (r.transport == "floor" ? 0.0 : r.msgs_per_s) << std::setw(8)
                << (r.has_copies ? std::to_string(r.copies) : "-") << "\n";
    }
    std::cout << std::setprecision(2) << "\np50(64 B, 1 sub) / floor p50      = " << ratio_floor
              << "   (target <= 1.5)\n"
              << "p50(1.5 MiB) / p50(64 B), 1 sub    = " << ratio_size << "   (target <= 1.2)\n"
              << "payload copies in 4-way fan-out    = " << fanout_copies << "   (target 0)\n"
              << std::setprecision(0) << "msgs/s at 64 B, busy consumer      = " << rate64
              << "   (target >= 1000000)\n";
    result = 0;
  });
}

}  // namespace tessera::app
