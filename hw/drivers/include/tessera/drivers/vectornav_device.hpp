// VectorNavDevice: an emulated VectorNav VN-100 IMU on its serial port (ASCII protocol), for
// testing the vectornav driver without the sensor (docs/architecture.md#device-drivers). Bytes
// in, bytes out, no I/O: EmulatorHost puts it on a pseudo-terminal.
//
// It answers VNRRG 1 (model), 3 (serial number), 5, 6, 7 and VNWRG 5 (baud: the reply goes out
// at the old rate, then it switches), 6 (output type 0, 1 VNYPR, 8 VNYMR, 19 VNIMU) and 7
// (rate) as the manual describes. Refusals: VNERR 3 for a bad checksum ("*XX" means none), 4 an
// unknown command, 5/6 too few/many values, 7 a value the register does not take, 8 an unknown
// register, 9 a read-only one, 12 an output the baud rate cannot carry. It powers up at
// `power_up_baud` streaming VNYMR at 40 Hz, like a VN-100 from the factory, and streams the
// selected output at the set rate; a line the baud rate cannot carry before the next is due is
// skipped. The motion (set by the test) is a constant angular velocity and specific force in
// REP-103, with optional noise: VNYMR's yaw integrates it. Faults as the other emulators
// (DeviceFaults): garbage, corrupted bytes, silence, late replies.
#pragma once

#include <tessera/drivers/device_faults.hpp>
#include <tessera/drivers/outgoing_bytes.hpp>
#include <tessera/drivers/vectornav.hpp>

#include <array>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <string_view>

namespace tessera::drivers {

/// What the emulated IMU feels, REP-103 (x forward, y left, z up).
struct VectorNavMotion {
  std::array<double, 3> angular_velocity{0, 0, 0};      ///< [rad/s]; z > 0 turns left
  std::array<double, 3> specific_force{0, 0, 9.80665};  ///< [m/s^2]; at rest +g on z
  double gyro_noise = 0;                                ///< [rad/s] standard deviation
  double accel_noise = 0;                               ///< [m/s^2] standard deviation
};

class VectorNavDevice {
 public:
  static constexpr const char* kModel = "VN-100T-CR";
  static constexpr const char* kSerialNumber = "0100012345";

  explicit VectorNavDevice(int power_up_baud = 115200, std::uint64_t seed = 1);

  void receive(std::string_view bytes, std::int64_t now_ns);
  std::string poll(std::int64_t now_ns);
  std::optional<std::int64_t> nextDue() const;
  /// The rate its UART is at now.
  int baud() const { return baud_; }
  /// Power cycle: the power-up baud rate and output (its settings were not saved).
  void restart(std::int64_t now_ns);

  VectorNavMotion& motion() { return motion_; }
  DeviceFaults& faults() { return faults_; }
  int outputType() const { return type_; }
  int outputRate() const { return rate_hz_; }
  std::int64_t linesSent() const { return lines_sent_; }
  std::int64_t linesSkipped() const { return lines_skipped_; }
  std::int64_t commandsReceived() const { return commands_; }

 private:
  void command(const vn::Message& m, std::int64_t now_ns);
  void reply(const std::string& body, std::int64_t now_ns);
  void error(int code, std::int64_t now_ns);
  std::string sampleLine(std::int64_t at_ns);
  std::int64_t lineTime(std::size_t bytes) const;
  bool carries(int type, int rate_hz, int baud) const;

  int power_up_baud_;
  VectorNavMotion motion_;
  DeviceFaults faults_;
  std::mt19937_64 rng_;
  vn::LineSplitter splitter_;
  int baud_;
  int type_ = vn::kTypeYmr, rate_hz_ = 40;
  double yaw_deg_ = 0;  // VN-100 heading: clockwise seen from above
  std::int64_t last_ns_ = 0, next_line_ns_ = 0, line_free_ns_ = 0;
  OutgoingBytes outgoing_;  // replies and output lines in due order; the baud change after them
  std::int64_t lines_sent_ = 0, lines_skipped_ = 0, commands_ = 0;
};

}  // namespace tessera::drivers
