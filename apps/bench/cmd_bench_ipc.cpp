// tessera bench ipc: latency and throughput between two processes of one machine, in the shape
// of iceoryx's iceperf (a leader pings, a follower answers with a pong of the same size), for
//  * iceoryx      our shared-memory transport: one Runtime per process, Cap'n Proto msg::Blob
//                 messages built in loaned chunks (ShmTransport), actors on both ends;
//  * iceoryx_raw  raw iceoryx chunks (UntypedPublisher/UntypedSubscriber, WaitSet): the floor;
//  * uds          a Unix-domain stream socket, the full payload copied each way;
//  * inproc       the same two actors in one Runtime, no transport, for reference.
// RouDi is embedded in this process (RouDiHost); leader and follower are forked children, always
// reaped (and killed on error, timeout or Ctrl-C), so no process or shared memory outlives it.
//
// Latency: the leader asks the follower to build its pong and waits for the confirmation, builds
// its ping (application work, not latency), waits a gap so both sides are idle, then stamps
// steady_clock and publishes (gap 1 ms by default: a message after a quiet
// spell, as sensor data arrives; with --gap-us 100 on an idle VM raw iceoryx's two
// single-threaded processes answer in ~8 us while ours and the socket take ~20 us, on a VM
// loaded by other jobs all three are near 10 us). The follower stamps on take and sends the
// prebuilt pong, which carries the ping's one-way latency and its own stamp. So no payload is
// being written anywhere while a message is under way (writing MiBs slows this VM's wake-ups).
// --fill says what building writes: `first-use` (default; iceperf's method, under which the
// reference figures in docs/benchmarks.md were taken: raw iceoryx flat at every size) writes a
// buffer or chunk in full the first time it is used and afterwards only its header; `every`
// writes every payload in full, as a producer filling each image would. Writing MiBs before each
// message evicts the caches the next wake-up runs from (every zero-copy transport then slows with
// size, raw iceoryx too) and leaves the socket's source bytes hot for its copy: the two modes
// bracket what an application sees. CLOCK_MONOTONIC is system-wide, so stamps of two processes
// compare. The two directions are kept apart: the ping wakes a process idle since the gap, the pong
// one that has just sent, so they form two modes and a median over both pooled would land in either
// from run to run. The one-way p50 is the mean of the two medians; p99 is over both. Round trip is
// ping stamp to pong take. Streaming: the leader publishes 64 B messages as fast as it can for
// --stream-seconds on a reliable (blocking) path; the follower counts them and reports the count
// when told the end.
//
// The parts: wire format and protocol (ipc/wire.hpp, ipc/protocol.hpp), one file per transport
// (ipc/transport_*.cpp), process control (ipc/processes.hpp) and the report (ipc/report.hpp).
#include "bench_commands.hpp"
#include "ipc/processes.hpp"
#include "ipc/report.hpp"
#include "ipc/transports.hpp"

#include <tessera/runtime/options.hpp>
#include <tessera/shm/roudi_host.hpp>
#include <tessera/shm/shm_transport.hpp>

#include <unistd.h>

#include <algorithm>
#include <memory>

namespace tessera::app {

namespace {

using namespace ipc;

std::vector<MemPool> benchPools() {
  std::vector<ChunkDemand> demands;
  for (std::size_t bytes : kSizes) {
    demands.push_back({bytes, 8});  // raw chunks
    // Cap'n Proto Blob loans: the payload in the message, or beside it (loanWithBlob) after
    // a first segment of the default size.
    demands.push_back({bytes + kShmDefaultMessageBytes + 1024 + 2 * kShmChunkOverhead, 8});
  }
  // Streaming: subscriber queues and mailboxes full of small messages on both paths.
  demands.push_back({kShmDefaultMessageBytes + 1024 + kShmChunkOverhead, 512});
  demands.push_back({kStreamBytes, 512});
  return memPoolsFor(demands);
}

void runBench(const Options& o) {
  if (o.samples < 1) throw ConfigError("bench ipc: --samples must be at least 1");
  if (o.rounds < 1) throw ConfigError("bench ipc: --rounds must be at least 1");
  if (o.gap_us < 0) throw ConfigError("bench ipc: --gap-us must not be negative");
  if (o.stream_seconds <= 0) throw ConfigError("bench ipc: --stream-seconds must be positive");
  // What one round of one transport does.
  Options round = o;
  round.samples = (o.samples + o.rounds - 1) / o.rounds;
  round.stream_seconds = o.stream_seconds / o.rounds;
  if (round.samples > kMaxRoundSamples) {
    throw ConfigError("bench ipc: at most " + std::to_string(kMaxRoundSamples) +
                      " samples per round; raise --rounds");
  }
  InterruptGuard interrupts;
  std::vector<Row> rows;
  {
    const auto pools = benchPools();
    std::size_t max_chunk = 0;
    for (const auto& p : pools) max_chunk = std::max(max_chunk, p.chunk_bytes);
    // Every child is forked here, before RouDi's threads exist (see PairRun).
    std::vector<std::unique_ptr<SocketPair>> sockets;
    std::array<std::vector<std::unique_ptr<PairRun>>, 3> pairs;  // ours, raw, uds
    for (int r = 0; r < o.rounds; ++r) {
      pairs[0].push_back(std::make_unique<PairRun>(
          "iceoryx", [&, r](TransportResult& out) { shmLeader(max_chunk, round, out, r); },
          [&, r] { return shmFollower(max_chunk, o.fill, r); },
          std::vector<std::string>{roundName(kShmLeaderName, r), roundName(kShmFollowerName, r)}));
      pairs[1].push_back(std::make_unique<PairRun>(
          "iceoryx_raw", [&, r](TransportResult& out) { rawLeader(round, out, r); },
          [&o, r] { return rawFollower(o.fill, r); },
          std::vector<std::string>{roundName(kRawLeaderName, r), roundName(kRawFollowerName, r)}));
      const int* fds = sockets.emplace_back(std::make_unique<SocketPair>())->fds;
      // Each child closes the other end, so a dead peer shows as a closed socket.
      pairs[2].push_back(std::make_unique<PairRun>(
          "uds",
          [&round, fds](TransportResult& out) {
            ::close(fds[1]);
            udsLeader(fds[0], round, out);
          },
          [&o, fds] {
            ::close(fds[0]);
            return udsFollower(fds[1], o.fill);
          }));
    }
    // RouDi prints its start-up to stdout, which belongs to the report (one JSON object).
    StdoutToStderr quiet;
    RouDiHost roudi(RouDiHostOptions{pools});
    if (roudi.maxChunkBytes() != max_chunk) throw std::logic_error("bench ipc: pool sizes");
    std::array<std::vector<const TransportResult*>, 3> results;
    for (int r = 0; r < o.rounds; ++r) {
      for (std::size_t t = 0; t < pairs.size(); ++t) {
        results[t].push_back(&pairs[t][static_cast<std::size_t>(r)]->run(round));
      }
    }
    addRows(rows, "iceoryx", results[0], true);
    addRows(rows, "iceoryx_raw", results[1], false);
    addRows(rows, "uds", results[2], false);
  }
  // In-process: no other process involved; its rounds run back to back.
  std::vector<std::unique_ptr<TransportResult>> inproc;
  for (int r = 0; r < o.rounds; ++r) {
    inprocRun(round, *inproc.emplace_back(std::make_unique<TransportResult>()));
    InterruptGuard::check();
  }
  std::vector<const TransportResult*> inproc_rounds;
  for (const auto& r : inproc) inproc_rounds.push_back(r.get());
  addRows(rows, "inproc", inproc_rounds, false);
  // Table order: by transport then size, as measured.
  print(rows, evaluate(rows), o);
}

}  // namespace

void addBenchIpcCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "ipc",
      "latency and throughput between two processes: our iceoryx transport vs raw "
      "iceoryx, a Unix socket and in-process");
  auto o = std::make_shared<Options>();
  cmd->add_option("--samples", o->samples, "ping-pongs per transport and payload size");
  cmd->add_option("--rounds", o->rounds,
                  "rounds in which the transports take turns (samples are split over them)");
  cmd->add_option("--gap-us", o->gap_us, "idle gap between ping-pongs [us]");
  cmd->add_option("--stream-seconds", o->stream_seconds, "duration of each 64 B streaming run [s]");
  auto fill = std::make_shared<std::string>(fillName(o->fill));
  cmd->add_option("--fill", *fill,
                  "what building a message writes: first-use (a buffer in full when first used, "
                  "then only its header, as iceperf does) or every (each payload in full)")
      ->check(CLI::IsMember({fillName(Fill::kFirstUse), fillName(Fill::kEvery)}));
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, fill, &result] {
    o->fill = *fill == fillName(Fill::kEvery) ? Fill::kEvery : Fill::kFirstUse;
    runBench(*o);
    result = 0;
  });
}

}  // namespace tessera::app
