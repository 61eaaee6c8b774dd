// CreateDevice: an emulated iRobot Create 2 on its serial port (Open Interface), for testing
// the create_base driver without the robot (docs/architecture.md#device-drivers). Bytes in,
// bytes out, no I/O: EmulatorHost puts it on a pseudo-terminal.
//
// Off until Start; Passive after it (sensors, no driving); Safe and Full drive. Drive Direct
// sets the wheel speeds, which turn the encoders at 508.8 counts per revolution of a 72 mm
// wheel. Stream sends a frame of the requested packets every 15 ms. In Safe mode a cliff or a
// wheel drop stops the wheels and drops to Passive, as the real robot does. The test sets the
// world: bumpers, cliffs, wheel drops, battery.
#pragma once

#include <tessera/drivers/create_oi.hpp>
#include <tessera/drivers/device_faults.hpp>

#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <string_view>

namespace tessera::drivers {

class CreateDevice {
 public:
  enum class Mode { kOff, kPassive, kSafe, kFull };
  explicit CreateDevice(std::uint64_t seed = 1);

  void receive(std::string_view bytes, std::int64_t now_ns);
  std::string poll(std::int64_t now_ns);
  std::optional<std::int64_t> nextDue() const;
  void restart(std::int64_t now_ns);

  /// What the robot's sensors see; encoder counts are the device's own.
  oi::SensorFrame& world() { return world_; }
  DeviceFaults& faults() { return faults_; }
  Mode mode() const { return mode_; }
  double rightSpeed() const { return right_mm_s_; }  ///< [mm/s] the wheels now
  double leftSpeed() const { return left_mm_s_; }
  /// [m] distance each wheel rolled since power-up.
  double rightDistance() const { return right_m_; }
  double leftDistance() const { return left_m_; }

 private:
  void advance(std::int64_t now_ns);
  void execute(std::int64_t now_ns);

  DeviceFaults faults_;
  std::mt19937_64 rng_;
  Mode mode_ = Mode::kOff;
  std::string command_;  // bytes of a command still waiting for its arguments
  oi::SensorFrame world_;
  double right_mm_s_ = 0, left_mm_s_ = 0, right_m_ = 0, left_m_ = 0;
  std::int64_t last_ns_ = 0;
  bool streaming_ = false;
  std::int64_t next_frame_ns_ = 0;
};

}  // namespace tessera::drivers
