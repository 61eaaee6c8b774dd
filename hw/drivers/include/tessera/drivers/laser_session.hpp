// LaserSession: what every laser driver's protocol core is to the driver loop that owns the
// device (docs/architecture.md#device-drivers): a state machine with no I/O. The loop opens the
// link at openBaud(), calls connected(), hands it every byte it reads, ticks it, and does what
// each SessionOutput says: write bytes, switch the port's baud rate, publish scans, log events,
// or drop the link and reconnect.
//
// Units: time is host int64 ns; ranges are metres in the laser frame, angles counter-clockwise
// with 0 ahead.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::drivers {

/// One scan, ready to publish.
struct LaserReading {
  std::int64_t stamp_ns = 0;           ///< host time the scan was taken (estimated)
  std::int64_t received_ns = 0;        ///< host time its last byte was read
  float angle_min = 0;                 ///< [rad] first beam
  float angle_increment = 0;           ///< [rad]
  float range_min = 0, range_max = 0;  ///< [m] the sensor's limits
  float scan_time = 0;                 ///< [s] one sweep
  std::vector<float> ranges;           ///< [m]; +inf no return, NaN error code
  std::vector<float> intensities;      ///< empty when the sensor gives none
};

struct SessionOutput {
  int switch_baud = 0;              ///< > 0: set the port to this rate, then write `send`
  std::string send;                 ///< bytes to write to the device
  std::vector<LaserReading> scans;  ///< good scans, in order
  std::vector<std::string> events;  ///< what happened, for the log (connect, errors)
  bool reconnect = false;           ///< close the link, back off, open it again
  std::string reconnect_reason;
};

struct SessionCounters {
  std::int64_t scans = 0;           ///< good scans returned
  std::int64_t bad_replies = 0;     ///< checksum, framing or decoding failures (dropped)
  std::int64_t refusals = 0;        ///< commands the device refused
  std::int64_t sessions = 0;        ///< handshakes completed (streaming began)
  std::uint64_t garbage_bytes = 0;  ///< bytes that were not part of any reply
};

class LaserSession {
 public:
  virtual ~LaserSession() = default;
  /// The baud rate to open the port with for the next attempt (`configured` is the driver's
  /// option); a session that searches for the device's rate cycles through its list here.
  virtual int openBaud(int configured) { return configured; }
  /// The link is open: starts the handshake.
  virtual SessionOutput connected(std::int64_t now_ns) = 0;
  /// The link closed (by the device or after `reconnect`): forgets the session.
  virtual void disconnected() = 0;
  /// Bytes read from the link at `now_ns`.
  virtual SessionOutput received(std::string_view bytes, std::int64_t now_ns) = 0;
  /// Checks the timeouts; call it at least every 100 ms.
  virtual SessionOutput tick(std::int64_t now_ns) = 0;
  virtual bool streaming() const = 0;
  virtual SessionCounters counters() const = 0;
  /// The device's model as it reported it ("" before the handshake got it).
  virtual std::string model() const = 0;
};

}  // namespace tessera::drivers
