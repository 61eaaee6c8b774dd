// `bench ipc` report (report.hpp): medians per direction and percentiles over the pooled rounds,
// the targets, and the table or JSON object.
#include "report.hpp"

#include "../bench_util.hpp"

#include <tessera/runtime/process_stats.hpp>

#include <nlohmann/json.hpp>

#include <iomanip>
#include <iostream>
#include <stdexcept>
#include <utility>

namespace tessera::app::ipc {

std::vector<Target> evaluate(const std::vector<Row>& rows) {
  auto find = [&](const std::string& transport, std::size_t payload) -> const Row& {
    for (const auto& r : rows)
      if (r.transport == transport && r.payload == payload) return r;
    throw std::logic_error("bench ipc: missing row");
  };
  // The largest ours / raw ratio of `field` over the sizes, and the size it is at.
  auto worstOverRaw = [&](double SizeResult::*field) {
    std::pair<double, std::size_t> worst{0.0, 0};
    for (std::size_t bytes : kSizes) {
      const double ratio = find("iceoryx", bytes).r.*field / find("iceoryx_raw", bytes).r.*field;
      if (ratio > worst.first) worst = {ratio, bytes};
    }
    return worst;
  };
  std::vector<Target> t;
  const auto [worst, worst_at] = worstOverRaw(&SizeResult::p50_us);
  t.push_back({"iceoryx_over_raw_p50_worst",
               "one-way p50, ours / raw iceoryx, worst at " + std::to_string(worst_at) + " B",
               worst, 1.5, true, worst_at});
  const double flat =
      find("iceoryx", kSizes.back()).r.p50_us / find("iceoryx", kSizes.front()).r.p50_us;
  t.push_back({"iceoryx_p50_4MiB_over_64B", "one-way p50, ours, 4 MiB / 64 B", flat, 1.3, true});
  t.push_back({"uds_over_iceoryx_p50_1MiB", "one-way p50 at 1 MiB, Unix socket / ours",
               find("uds", kSizes[2]).r.p50_us / find("iceoryx", kSizes[2]).r.p50_us, 25, false});
  t.push_back({"uds_over_iceoryx_p50_4MiB", "one-way p50 at 4 MiB, Unix socket / ours",
               find("uds", kSizes[3]).r.p50_us / find("iceoryx", kSizes[3]).r.p50_us, 100, false});
  // The same ratios on round trips, the figure iceperf reports (and the reference figures in
  // docs/benchmarks.md are): a round trip adds both directions, whose wake-ups on this VM are
  // bimodal in different proportions, so its median need not be twice the pooled one-way median.
  const auto [rtt_worst, rtt_worst_at] = worstOverRaw(&SizeResult::rtt_p50_us);
  t.push_back(
      {"iceoryx_over_raw_rtt_p50_worst",
       "round-trip p50, ours / raw iceoryx, worst at " + std::to_string(rtt_worst_at) + " B",
       rtt_worst, 1.5, true, rtt_worst_at});
  t.push_back({"uds_over_iceoryx_rtt_p50_1MiB", "round-trip p50 at 1 MiB, Unix socket / ours",
               find("uds", kSizes[2]).r.rtt_p50_us / find("iceoryx", kSizes[2]).r.rtt_p50_us, 25,
               false});
  t.push_back({"uds_over_iceoryx_rtt_p50_4MiB", "round-trip p50 at 4 MiB, Unix socket / ours",
               find("uds", kSizes[3]).r.rtt_p50_us / find("iceoryx", kSizes[3]).r.rtt_p50_us, 100,
               false});
  t.push_back({"iceoryx_msgs_per_s_64B", "streaming msgs/s at 64 B, ours",
               find("iceoryx", kStreamBytes).msgs_per_s.value_or(0), 300000, false});
  return t;
}

void addRows(std::vector<Row>& rows, const std::string& transport,
             const std::vector<const TransportResult*>& rounds, bool has_copies) {
  std::int64_t streamed = 0;
  double stream_s = 0;
  for (const auto* r : rounds) {
    streamed += r->streamed;
    stream_s += r->stream_s;
  }
  for (std::size_t k = 0; k < kSizes.size(); ++k) {
    std::vector<double> one_way, ping, pong, round_trip;
    SizeResult size;
    for (const auto* r : rounds) {
      const RoundSamples& s = r->sizes[k];
      one_way.insert(one_way.end(), s.one_way.begin(), s.one_way.begin() + 2 * s.count);
      for (int i = 0; i < s.count; ++i) {
        ping.push_back(s.one_way[2 * static_cast<std::size_t>(i)]);
        pong.push_back(s.one_way[2 * static_cast<std::size_t>(i) + 1]);
      }
      round_trip.insert(round_trip.end(), s.round_trip.begin(), s.round_trip.begin() + s.count);
      size.copies += s.copies;
    }
    // Last uses are moved in (percentile() sorts its own copy).
    size.ping_p50_us = percentile(std::move(ping), 0.5);
    size.pong_p50_us = percentile(std::move(pong), 0.5);
    size.p50_us = 0.5 * (size.ping_p50_us + size.pong_p50_us);
    size.p99_us = percentile(std::move(one_way), 0.99);
    size.rtt_p50_us = percentile(round_trip, 0.5);
    size.rtt_p99_us = percentile(std::move(round_trip), 0.99);
    Row row{transport, kSizes[k], size, std::nullopt, has_copies};
    if (kSizes[k] == kStreamBytes && stream_s > 0) {
      row.msgs_per_s = static_cast<double>(streamed) / stream_s;
    }
    rows.push_back(row);
  }
}

void print(const std::vector<Row>& rows, const std::vector<Target>& targets, const Options& o) {
  if (o.json) {
    nlohmann::json j;
    j["machine"] = machineDescription();
    j["gap_us"] = o.gap_us;
    j["samples"] = o.samples;
    j["rounds"] = o.rounds;
    j["fill"] = fillName(o.fill);
    for (const auto& r : rows) {
      j["results"].push_back(
          {{"transport", r.transport},
           {"payload_bytes", r.payload},
           {"subscribers", 1},
           {"p50_us", r.r.p50_us},
           {"ping_p50_us", r.r.ping_p50_us},
           {"pong_p50_us", r.r.pong_p50_us},
           {"p99_us", r.r.p99_us},
           {"round_trip_p50_us", r.r.rtt_p50_us},
           {"round_trip_p99_us", r.r.rtt_p99_us},
           {"msgs_per_s", r.msgs_per_s ? nlohmann::json(*r.msgs_per_s) : nlohmann::json(nullptr)},
           {"payload_copies",
            r.has_copies ? nlohmann::json(r.r.copies) : nlohmann::json(nullptr)}});
    }
    j["targets"] = nlohmann::json::object();
    for (const auto& t : targets) {
      j["targets"][t.name] = {
          {"value", t.value}, {t.at_most ? "max" : "min", t.limit}, {"met", t.met()}};
      if (t.payload != 0) j["targets"][t.name]["payload_bytes"] = t.payload;
    }
    std::cout << j.dump(2) << "\n";
    return;
  }
  std::cout << "machine: " << machineDescription() << "\n"
            << "one-way latency: stamp before publish -> take in the other process; p50 is the "
               "mean of the ping and pong medians, p99 over both directions; "
            << o.samples << " ping-pongs per size in " << o.rounds << " rounds taking turns, gap "
            << o.gap_us << " us, payloads written " << fillName(o.fill)
            << " (--fill); round trip: ping stamp -> pong take\n\n";
  std::cout << std::left << std::setw(13) << "transport" << std::right << std::setw(10)
            << "payload B" << std::setw(10) << "p50 us" << std::setw(10) << "ping p50"
            << std::setw(10) << "pong p50" << std::setw(10) << "p99 us" << std::setw(12)
            << "rtt p50 us" << std::setw(12) << "rtt p99 us" << std::setw(12) << "msgs/s"
            << std::setw(8) << "copies"
            << "\n"
            << std::fixed;
  for (const auto& r : rows) {
    std::cout << std::left << std::setw(13) << r.transport << std::right << std::setw(10)
              << r.payload << std::setprecision(2) << std::setw(10) << r.r.p50_us << std::setw(10)
              << r.r.ping_p50_us << std::setw(10) << r.r.pong_p50_us << std::setw(10) << r.r.p99_us
              << std::setw(12) << r.r.rtt_p50_us << std::setw(12) << r.r.rtt_p99_us
              << std::setprecision(0) << std::setw(12)
              << (r.msgs_per_s ? std::to_string(static_cast<long>(*r.msgs_per_s)) : "-")
              << std::setw(8) << (r.has_copies ? std::to_string(r.r.copies) : "-") << "\n";
  }
  std::cout << "\n";
  for (const auto& t : targets) {
    std::cout << std::left << std::setw(56) << t.description << std::right
              << std::setprecision(t.value >= 1000 ? 0 : 2) << std::setw(12) << t.value << "   "
              << (t.at_most ? "<= " : ">= ") << std::setprecision(t.limit >= 1000 ? 0 : 1)
              << t.limit << (t.met() ? "   met" : "   NOT met") << "\n";
  }
}

}  // namespace tessera::app::ipc
