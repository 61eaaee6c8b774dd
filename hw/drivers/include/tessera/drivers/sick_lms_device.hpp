// SickLmsDevice: an emulated SICK LMS200 on its serial line, from the telegram listing, for
// testing the sick_lms driver without the sensor (docs/architecture.md#device-drivers). Bytes
// in, bytes out, no I/O: EmulatorHost puts it on a pseudo-terminal.
//
// It powers up at 9600 baud in request mode with the 180 deg / 1 deg variant and cm units. It
// acknowledges every telegram (ACK, or NAK when the CRC fails), answers 0x20 (stop, stream,
// baud changes, installation mode with its password), 0x3B (variants the LMS has), 0x74/0x77
// (the configuration; writing it needs installation mode) and streams 0xB0 scans at 75 Hz per
// interlaced sweep (1 deg: 75 Hz, 0.5 deg: 37.5 Hz, 0.25 deg: 18.75 Hz). A scan that the line
// cannot carry before the next is due at the current baud rate is skipped, as on the real
// sensor at 9600-38400 baud. Faults as the other emulators (DeviceFaults).
#pragma once

#include <tessera/drivers/device_faults.hpp>
#include <tessera/drivers/outgoing_bytes.hpp>
#include <tessera/drivers/sick_lms.hpp>

#include <cstdint>
#include <functional>
#include <optional>
#include <random>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::drivers {

/// The ranges of one sweep in mm, one per beam of the current variant (angle/resolution + 1,
/// from the right); ranges the sensor cannot measure are 0 (no echo).
using LmsScanSource =
    std::function<std::vector<std::uint32_t>(int angle_deg, int resolution_centideg)>;

class SickLmsDevice {
 public:
  explicit SickLmsDevice(LmsScanSource source, std::uint64_t seed = 1);

  void receive(std::string_view bytes, std::int64_t now_ns);
  std::string poll(std::int64_t now_ns);
  std::optional<std::int64_t> nextDue() const;
  /// The rate the device's UART is at now.
  int baud() const { return baud_; }
  /// Power cycle: 9600 baud, request mode (the configuration is kept: it is in EEPROM).
  void restart(std::int64_t now_ns);
  DeviceFaults& faults() { return faults_; }

  std::int64_t scansSent() const { return scans_sent_; }
  std::int64_t scansSkipped() const { return scans_skipped_; }
  bool streaming() const { return streaming_; }
  bool millimetres() const { return static_cast<std::uint8_t>(config_[sick::kUnitsByte]) == 1; }

 private:
  void handle(const sick::Telegram& t, std::int64_t now_ns);
  void reply(const std::string& payload, std::int64_t now_ns);
  std::int64_t lineTime(std::size_t bytes) const;

  LmsScanSource source_;
  DeviceFaults faults_;
  std::mt19937_64 rng_;
  sick::TelegramParser parser_;
  int baud_ = 9600;
  bool streaming_ = false, installation_ = false;
  int angle_deg_ = 180, resolution_centideg_ = 100;
  std::string config_;
  std::uint8_t status_ = 0x10;  // the listing's "no error" status with the 8 m / 80 m flag
  std::int64_t next_scan_ns_ = 0, line_free_ns_ = 0;
  OutgoingBytes outgoing_;  // in the order queued; the baud change after them
  std::int64_t scans_sent_ = 0, scans_skipped_ = 0;
};

}  // namespace tessera::drivers
