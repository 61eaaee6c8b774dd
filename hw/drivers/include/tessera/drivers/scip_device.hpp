// ScipDevice: an emulated Hokuyo laser speaking SCIP 2.0, for testing drivers without hardware
// and for trying the stack on a recorded log (`tessera emulate scip`;
// docs/architecture.md#device-drivers). Bytes in, bytes out, no I/O: EmulatorHost puts it on a
// pseudo-terminal or a TCP port.
//
// It answers SCIP2.0, QT, BM, RS, PP, VV and the scan commands MD/MS/ME (streamed, one scan per
// revolution from its scan source) and GD/GS (one scan), as the specification describes: echo,
// status with checksum, data lines of 64 characters. It refuses what a real device refuses:
// unknown commands with status "0E", steps outside AMIN..AMAX with "10". Faults a test can
// switch on: garbage bytes before replies, corrupted data bytes (their checksum fails), a device
// that stops answering, one that answers late.
//
// Time is host ns, given by the caller; the device's own counter (the scans' timestamps) is
// ms since it was created, or the source's stamps when it has them.
#pragma once

#include <tessera/drivers/device_faults.hpp>
#include <tessera/drivers/outgoing_bytes.hpp>
#include <tessera/drivers/scip.hpp>

#include <cstdint>
#include <functional>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::drivers {

/// One revolution's readings over every step AMIN..AMAX, as the sensor measured them.
struct EmulatedScan {
  std::vector<std::uint32_t> ranges_mm;    ///< AMAX - AMIN + 1 values
  std::vector<std::uint32_t> intensities;  ///< empty: ME answers 0
  std::optional<std::uint32_t> sensor_ms;  ///< the device's stamp; default its own clock
  std::int64_t period_ns = 0;              ///< time to the next scan; 0 = one revolution
};

/// The next scan of the emulated world; nullopt at the end (the device goes quiet).
using ScanSource = std::function<std::optional<EmulatedScan>()>;

class ScipDevice {
 public:
  /// A URG-04LX: steps 44..725 of 1024, front 384, 20..5600 mm, 600 rpm.
  static scip::SensorParameters urg04lx();

  ScipDevice(scip::SensorParameters parameters, ScanSource source, std::uint64_t seed = 1);

  /// Command bytes from the host at `now_ns` (any chunks); replies are queued.
  void receive(std::string_view bytes, std::int64_t now_ns);
  /// The bytes due by `now_ns`: replies and streamed scans.
  std::string poll(std::int64_t now_ns);
  /// When poll() next has something to send; nullopt when nothing is pending.
  std::optional<std::int64_t> nextDue() const;

  DeviceFaults& faults() { return faults_; }
  /// Power cycle: stream stopped, laser off, its clock restarted at `now_ns`.
  void restart(std::int64_t now_ns);

  std::int64_t scansSent() const { return scans_sent_; }
  std::int64_t commandsReceived() const { return commands_; }
  bool sourceEnded() const { return source_ended_; }

 private:
  struct Stream {
    std::string echo;  // command line as received, scan count at its end (MD/MS/ME)
    int first = 0, last = 0, cluster = 1, interval = 0, remaining = 0;  // 0 remaining = forever
    int chars = 3;
    bool intensity = false;
    std::int64_t next_ns = 0;
    int skipped = 0;
  };
  void command(const std::string& line, std::int64_t now_ns);
  void queue(std::string bytes, std::int64_t now_ns);
  std::string scanReply(const std::string& echo, const std::string& status, const Stream& s,
                        const EmulatedScan& scan, std::int64_t now_ns);
  std::optional<Stream> parseScanCommand(const std::string& line, std::string& status) const;

  scip::SensorParameters params_;
  ScanSource source_;
  DeviceFaults faults_;
  std::mt19937_64 rng_;
  std::string line_;
  OutgoingBytes outgoing_;  // in the order queued
  std::optional<Stream> stream_;
  bool laser_on_ = false;
  std::int64_t clock_zero_ns_ = 0;
  std::int64_t scans_sent_ = 0, commands_ = 0;
  bool source_ended_ = false;
};

}  // namespace tessera::drivers
