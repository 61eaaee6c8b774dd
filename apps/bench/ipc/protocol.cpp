// `bench ipc` leader's side of a round (protocol.hpp): ping-pongs with the sizes taking turns,
// then streaming; the samples go into the round's TransportResult.
#include "protocol.hpp"

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>

namespace tessera::app::ipc {

namespace {

// First exchanges of every size (cold chunks, page faults) are not counted.
constexpr int kWarmup = 5;

/// One ping-pong of `bytes`; adds its one-way (both directions) and round-trip samples unless
/// warming up, and the messages either side copied to `copies`.
void pingPong(LeaderLink& link, std::size_t bytes, const Options& o, bool record,
              RoundSamples& samples, std::uint64_t& follower_copies) {
  const std::uint64_t own_copies = link.copies();
  link.build(kControlBytes, Kind::kPrepare, static_cast<std::int64_t>(bytes));
  link.send();
  if (link.receive().first.kind != Kind::kReady) {
    throw std::runtime_error("leader: the follower did not confirm its pong was ready");
  }
  link.build(bytes, Kind::kPing);
  std::this_thread::sleep_for(std::chrono::microseconds(o.gap_us));
  // The payload's stores are done before the stamp (large memsets may use non-temporal
  // stores that would otherwise drain inside the publish call and count as delivery).
  std::atomic_thread_fence(std::memory_order_seq_cst);
  const Nanos sent = link.send();
  const auto [pong, taken] = link.receive();
  if (pong.kind != Kind::kPong || pong.bytes != bytes) {
    throw std::runtime_error("leader: unexpected answer (kind " +
                             std::to_string(static_cast<int>(pong.kind)) + ", " +
                             std::to_string(pong.bytes) + " bytes)");
  }
  samples.copies += (link.copies() - own_copies) + (pong.copies - follower_copies);
  follower_copies = pong.copies;
  if (!record) return;
  const auto n = static_cast<std::size_t>(samples.count++);
  samples.one_way[2 * n] = static_cast<float>(static_cast<double>(pong.value) * 1e-3);
  samples.one_way[2 * n + 1] = static_cast<float>(static_cast<double>(taken - pong.stamp) * 1e-3);
  samples.round_trip[n] = static_cast<float>(static_cast<double>(taken - sent) * 1e-3);
}

}  // namespace

void lead(LeaderLink& link, const Options& o, TransportResult& out) {
  if (o.samples > kMaxRoundSamples) throw std::logic_error("bench ipc: round too long");
  // Sizes take turns, so a drift of the machine over the run (other load, a slower phase of
  // the VM) affects every size alike and the size ratios stay meaningful.
  std::uint64_t follower_copies = 0;
  for (int i = 0; i < o.samples + kWarmup; ++i) {
    for (std::size_t k = 0; k < kSizes.size(); ++k) {
      pingPong(link, kSizes[k], o, i >= kWarmup, out.sizes[k], follower_copies);
    }
  }

  // Streaming: as fast as the blocking path takes them, then the count from the follower.
  std::int64_t sent = 0;
  const Nanos start = steadyNow();
  const auto budget = static_cast<Nanos>(o.stream_seconds * 1e9);
  while (steadyNow() - start < budget) {
    for (int k = 0; k < 64; ++k, ++sent) {
      link.build(kStreamBytes, Kind::kStream);
      link.send();
    }
  }
  link.build(kControlBytes, Kind::kStreamEnd);
  link.send();
  const auto [count, taken] = link.receive();
  if (count.kind != Kind::kReady || count.value != sent) {
    throw std::runtime_error("leader: follower counted " + std::to_string(count.value) + " of " +
                             std::to_string(sent) + " streamed messages");
  }
  out.streamed = sent;
  out.stream_s = static_cast<double>(taken - start) * 1e-9;
  link.build(kControlBytes, Kind::kQuit);
  link.send();
  out.complete = true;
}

}  // namespace tessera::app::ipc
