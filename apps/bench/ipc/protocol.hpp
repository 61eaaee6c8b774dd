// `bench ipc` protocol: what one round of one transport measures (ping-pongs of every size, then
// streaming), the samples it records, and the two roles every transport plays. A transport
// implements LeaderLink for the leader, whose lead() drives the round, and answers with
// FollowerLogic on the follower's side.
#pragma once

#include "wire.hpp"

#include <string>

namespace tessera::app::ipc {

struct Options {
  int samples = 1000;
  /// The process transports take turns in this many rounds (fresh processes each), so a
  /// change of the machine's state over the run (other load, a slower phase of the VM) affects
  /// all of them alike and their ratios stay meaningful.
  int rounds = 5;
  int gap_us = 1000;
  double stream_seconds = 1.0;
  Fill fill = Fill::kFirstUse;
  bool json = false;
};

/// Most ping-pongs per size one round records (--samples / --rounds).
constexpr int kMaxRoundSamples = 5000;

/// One round's samples of one payload size.
struct RoundSamples {
  std::array<float, 2 * kMaxRoundSamples> one_way{};  // [us], both directions of each exchange
  std::array<float, kMaxRoundSamples> round_trip{};   // [us]
  int count = 0;                                      // exchanges recorded
  std::uint64_t copies = 0;
};

/// What the leader measured in one round; lives in memory shared with the bench process.
struct TransportResult {
  std::array<RoundSamples, kSizes.size()> sizes{};
  std::int64_t streamed = 0;  // 64 B messages the follower counted while streaming
  double stream_s = 0;        // [s] from the first streamed message to the follower's count
  bool complete = false;
  std::array<char, 256> leader_error{}, follower_error{};  // what ended a child, if anything
};

/// Leader side of one transport: build() is application work, send() stamps and publishes the
/// built message, receive() blocks until the next pong and returns it with its take time.
class LeaderLink {
 public:
  virtual ~LeaderLink() = default;
  virtual void build(std::size_t bytes, Kind kind, std::int64_t value = 0) = 0;
  virtual Nanos send() = 0;
  virtual std::pair<Wire, Nanos> receive() = 0;
  /// Messages this process copied so far (zero-copy transports that fell back to a copy).
  virtual std::uint64_t copies() const { return 0; }
};

/// One round: `o.samples` ping-pongs per size, then `o.stream_seconds` of streaming, recorded in
/// `out` (out.complete at the end).
void lead(LeaderLink& link, const Options& o, TransportResult& out);

/// The follower's answer to one message: the prebuilt pong for a ping, a pong built (kPrepare)
/// or the stream count (kStreamEnd) confirmed by a control message. Returns false on quit.
/// prepare(bytes) returns the pong slot, built if it is not of `bytes`; send() publishes the
/// slot; control(wire) builds and sends a small message at once.
class FollowerLogic {
 public:
  template <typename Prepare, typename Send, typename Control>
  bool handle(const Wire& in, Nanos taken, std::uint64_t copies, Prepare&& prepare, Send&& send,
              Control&& control) {
    Wire answer;
    answer.kind = Kind::kReady;
    switch (in.kind) {
      case Kind::kPing: {
        void* p = prepare(in.bytes);
        Wire w = readWire(p);
        w.value = taken - in.stamp;
        w.copies = copies;
        w.kind = Kind::kPong;
        w.stamp = steadyNow();
        writeWire(p, w);
        send();
        return true;
      }
      case Kind::kPrepare:
        prepare(static_cast<std::size_t>(in.value));
        control(answer);
        return true;
      case Kind::kStream:
        ++streamed_;
        return true;
      case Kind::kStreamEnd:
        answer.value = streamed_;
        streamed_ = 0;
        control(answer);
        return true;
      default:
        return false;
    }
  }

 private:
  std::int64_t streamed_ = 0;
};

}  // namespace tessera::app::ipc
