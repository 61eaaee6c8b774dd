// CreateBase: the host side of an iRobot Create 2 (Open Interface) as a state machine, no I/O:
// drive commands in, wheel ticks and base status out, with the safety every base driver owes
// the robot (docs/architecture.md#device-drivers).
//
// Session: Start, then Safe (the robot also stops itself on a cliff or a wheel drop; Full
// with `full_mode`), then Stream of the bumps, cliffs, battery and encoder packets (a frame
// every 15 ms). No frame within frame_timeout_s asks for a reconnect.
//
// Safety, on top of the robot's own:
//  * watchdog: no drive command for watchdog_s while the wheels turn stops them;
//  * a bumper pressed stops the wheels and allows only reversing until it is released; a cliff
//    likewise; a wheel drop allows nothing until the wheel is back on the ground;
//  * every stop is reported with its reason (BaseStatus::stop_reason) and counted.
// Commands: vx [m/s], omega [rad/s] -> wheel speeds v -+ omega * wheel_base / 2, limited to
// max_speed_m_s (and the OI's 0.5 m/s); non-finite commands stop the wheels.
#pragma once

#include <tessera/drivers/create_oi.hpp>

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::drivers {

struct CreateBaseOptions {
  double wheel_base_m = 0.235;           ///< Create 2: 235 mm between the wheels
  double wheel_radius_m = 0.036;         ///< Create 2: 72 mm wheels
  double counts_per_revolution = 508.8;  ///< Create 2 encoders
  double max_speed_m_s = 0.5;            ///< wheel speed limit (the OI's own is 0.5)
  double watchdog_s = 0.5;               ///< no command for this long stops the wheels
  double frame_timeout_s = 0.5;          ///< no sensor frame for this long: reconnect
  bool full_mode = false;                ///< Full mode: the robot's own cliff stop is off

  template <class V>
  void visit(V& v) {
    v("wheel_base_m", wheel_base_m, "[m] distance between the wheels (Create 2: 0.235)");
    v("wheel_radius_m", wheel_radius_m, "[m] wheel radius (Create 2: 0.036)");
    v("counts_per_revolution", counts_per_revolution, "encoder counts per wheel turn (508.8)");
    v("max_speed_m_s", max_speed_m_s, "[m/s] wheel speed limit (at most the OI's 0.5)");
    v("watchdog_s", watchdog_s, "[s] no drive command for this long stops the wheels");
    v("frame_timeout_s", frame_timeout_s, "[s] no sensor frame for this long: reconnect");
    v("full_mode", full_mode,
      "OI Full mode (the robot's own cliff and wheel-drop stop off; ours stays); default Safe");
  }
};

struct BaseStatus {
  std::int64_t stamp_ns = 0;
  oi::SensorFrame sensors;
  bool moving = false;      ///< the last wheel command was not zero
  std::string stop_reason;  ///< why the driver stopped the wheels last ("" if it did not)
};

struct WheelTickReading {
  std::int64_t stamp_ns = 0;
  std::int64_t left = 0, right = 0;  ///< cumulative counts since the session began
};

struct BaseOutput {
  std::string send;
  std::vector<WheelTickReading> ticks;
  std::vector<BaseStatus> status;  ///< on every change of the sensors or the stop state, and 2 Hz
  std::vector<std::string> events;
  bool reconnect = false;
  std::string reconnect_reason;
};

class CreateBase {
 public:
  explicit CreateBase(CreateBaseOptions options);  // throws std::invalid_argument

  BaseOutput connected(std::int64_t now_ns);
  void disconnected();
  BaseOutput received(std::string_view bytes, std::int64_t now_ns);
  BaseOutput tick(std::int64_t now_ns);
  /// A drive command: vx [m/s] forward, omega [rad/s] counter-clockwise.
  BaseOutput command(double vx, double omega, std::int64_t now_ns);

  bool streaming() const { return streaming_; }
  struct Counters {
    std::int64_t frames = 0, bad_frames = 0, commands = 0, watchdog_stops = 0, safety_stops = 0,
                 refused_commands = 0;
    std::uint64_t garbage_bytes = 0;
  };
  Counters counters() const;

 private:
  void drive(BaseOutput& out, double right_mm_s, double left_mm_s);
  void stop(BaseOutput& out, const std::string& reason, std::int64_t now_ns);
  void publishStatus(BaseOutput& out, std::int64_t now_ns);
  /// Why a command with forward speed `vx` may not run now ("" when it may).
  std::string blocked(double vx) const;

  CreateBaseOptions options_;
  bool connected_ = false, streaming_ = false, moving_ = false;
  std::int64_t last_command_ns_ = 0, last_frame_ns_ = 0, last_status_ns_ = 0;
  double last_vx_ = 0;
  oi::StreamParser parser_{oi::frameBodyBytes(oi::streamedPackets())};
  oi::EncoderUnwrap left_, right_;
  oi::SensorFrame sensors_;
  std::string stop_reason_;
  Counters counters_;
  std::uint64_t garbage_before_ = 0, bad_before_ = 0;
};

}  // namespace tessera::drivers
