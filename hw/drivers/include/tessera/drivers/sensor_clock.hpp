// SensorClock: stamps a device's readings in host time from the device's own counter
// (docs/architecture.md#device-drivers).
//
// A sensor such as a Hokuyo laser stamps each scan with a free-running millisecond counter
// that wraps (24 bits: every 4.66 h) and starts at power-up, so its stamps say when a scan was
// taken but not in host time. The host sees when the scan's last byte arrived, which is later
// by the transfer time plus a varying delay (USB polling, scheduling). The offset between the
// two clocks is therefore the smallest (host receive - sensor) seen: the readings that came
// through fastest. It is taken over a sliding window so that the two clocks' drift (tens of
// ppm) is followed. A stamp is sensor time + that offset: the sensor's own timing, without the
// host's jitter.
//
// Units: sensor ticks in `tick_ns` nanoseconds (1 ms for SCIP) or at a tick rate (60 MHz for the
// Kinect v1); host time in int64 ns.
#pragma once

#include <cstdint>
#include <deque>
#include <optional>

namespace tessera::drivers {

class SensorClock {
 public:
  /// `bits`: the counter's width (it wraps at 2^bits); `window_ns`: how far back the offset
  /// looks.
  explicit SensorClock(int bits = 24, std::int64_t tick_ns = 1'000'000,
                       std::int64_t window_ns = 10'000'000'000);
  /// A counter of `ticks_per_second` (not a whole number of ns: the Kinect's 60 MHz).
  static SensorClock withTickRate(int bits, std::int64_t ticks_per_second,
                                  std::int64_t window_ns = 10'000'000'000);

  /// The host time of a reading stamped `ticks` by the sensor and received at `host_ns`. The
  /// counter is unwrapped: it is assumed never to go backwards (call reset() after the device
  /// restarts).
  std::int64_t stamp(std::uint32_t ticks, std::int64_t host_ns);

  /// Several streams sharing the counter (the Kinect's colour and depth): the host may get a
  /// reading after a later-taken one of another stream. A reading up to `ticks` behind the
  /// newest is then earlier, not a wrap, and the counter steps on from the newest. Throws
  /// std::invalid_argument for half the counter's range or more (it could not tell a wrap).
  void allowBackSteps(std::uint32_t ticks);

  /// Forgets the counter and the offset (a reconnect: the device may have restarted).
  void reset();

  /// The current offset host - sensor [ns]; nullopt before the first reading.
  std::optional<std::int64_t> offset() const;
  /// How often the counter wrapped since the last reset.
  std::int64_t wraps() const { return wraps_; }

 private:
  int bits_;
  std::int64_t tick_ns_, window_ns_;
  std::int64_t tick_den_ = 1;  // a tick is tick_ns_ / tick_den_ ns
  std::uint32_t max_back_ticks_ = 0;
  std::optional<std::uint32_t> last_ticks_;  // the newest reading's
  std::int64_t unwrapped_ticks_ = 0, wraps_ = 0;
  struct Sample {
    std::int64_t host_ns, offset_ns;
  };
  std::deque<Sample> lows_;  // increasing offsets, oldest first: a sliding-window minimum
};

}  // namespace tessera::drivers
