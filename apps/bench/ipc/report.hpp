// `bench ipc` report: the figures of each transport and payload size pooled over the rounds, the
// targets they are held to, printed as a table or as one JSON object (--json).
#pragma once

#include "protocol.hpp"

#include <optional>
#include <string>
#include <vector>

namespace tessera::app::ipc {

/// One-way figures keep the two directions apart before combining them: the ping wakes a
/// process idle since the gap, the pong one that has just sent, so their latencies form two
/// modes and a median over both pooled lands in either, run to run.
struct SizeResult {
  double p50_us = 0;       // mean of the ping and pong medians
  double ping_p50_us = 0;  // leader -> follower, after the idle gap
  double pong_p50_us = 0;  // follower -> leader, the answer
  double p99_us = 0;       // over every hop of both directions
  double rtt_p50_us = 0, rtt_p99_us = 0;
  std::uint64_t copies = 0;
};

struct Row {
  std::string transport;
  std::size_t payload = 0;
  SizeResult r;
  std::optional<double> msgs_per_s;
  bool has_copies = false;
};

struct Target {
  std::string name, description;
  double value = 0, limit = 0;
  bool at_most = true;      // value <= limit, else value >= limit
  std::size_t payload = 0;  // the size the value was taken at, when one of several
  bool met() const { return at_most ? value <= limit : value >= limit; }
};

/// The targets (ratios between transports and sizes) over a full set of rows.
std::vector<Target> evaluate(const std::vector<Row>& rows);

/// One row per size from the samples of every round of `transport`, pooled.
void addRows(std::vector<Row>& rows, const std::string& transport,
             const std::vector<const TransportResult*>& rounds, bool has_copies);

/// The table (or with o.json one JSON object) on stdout.
void print(const std::vector<Row>& rows, const std::vector<Target>& targets, const Options& o);

}  // namespace tessera::app::ipc
