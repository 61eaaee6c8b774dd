// OutgoingBytes: what an emulated device has yet to send, each piece due at a time, and a baud
// rate change that waits until it has gone out. The emulators (ScipDevice, SickLmsDevice,
// VectorNavDevice) queue their replies and streamed data at the time they go out and, at each
// poll(), send the ones that are due; this is that queue, kept once
// (docs/architecture.md#device-drivers).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace tessera::drivers {

class OutgoingBytes {
 public:
  /// `bytes` due at `due_ns`, after the queued bytes due by then and before the later ones: a
  /// late reply does not hold back what is due before it.
  void queue(std::int64_t due_ns, std::string bytes);
  /// `bytes` due at `due_ns`, or with the last bytes queued if they are due later: everything
  /// goes out in the order queued, a late reply holding back the ones after it.
  void append(std::int64_t due_ns, std::string bytes);
  /// The bytes due by `now_ns`, in the order they go out; they leave the queue.
  std::string take(std::int64_t now_ns);
  /// take(), and `baud` changed to the rate given to changeBaudWhenSent() once the queue is
  /// empty.
  std::string take(std::int64_t now_ns, int& baud);
  /// When the next bytes are due; nullopt when none are queued.
  std::optional<std::int64_t> nextDue() const;
  bool empty() const { return pending_.empty(); }
  /// Drops the queued bytes and a baud change (a power cycle).
  void clear();

  /// A device answers a baud change at the old rate, then switches: the next take() that leaves
  /// the queue empty changes its `baud` to `rate`.
  void changeBaudWhenSent(int rate) { baud_after_ = rate; }

 private:
  struct Pending {
    std::int64_t due_ns;
    std::string bytes;
  };
  std::vector<Pending> pending_;  // in the order they go out
  int baud_after_ = 0;            // 0: no change waiting
};

}  // namespace tessera::drivers
