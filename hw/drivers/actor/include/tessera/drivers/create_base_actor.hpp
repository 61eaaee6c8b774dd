// CreateBaseActor ("create_base"): an iRobot Create 2 (Roomba 500/600 Open Interface) on its
// serial cable, as a mobile base (docs/architecture.md#device-drivers).
//
// Subscribes (local topic name):
//   base_cmd     msg::Twist       keep_latest(1): vx [m/s], omega [rad/s] (base_controller's
//                                 output, or cmd_vel directly)
// Publishes:
//   wheel_ticks  msg::WheelTicks  every sensor frame (15 ms): cumulative encoder counts since the
//                                 session began, with the wheel geometry (wheel_gyro_odometry
//                                 makes odometry of them)
//   base_status  msg::BaseStatus  bumpers, cliffs, wheel drops, battery, and why the driver
//                                 stopped the wheels, on every change and at 2 Hz
//
// A DeviceLoop owns the port; the session (CreateBase) runs the OI in Safe mode and adds the
// driver's safety: a watchdog (no base_cmd for base.watchdog_s stops the wheels), bumper and
// cliff stops that allow only reversing, a wheel drop that allows nothing. Needs the wall clock.
#pragma once

#include <tessera/drivers/create_base.hpp>
#include <tessera/drivers/device_loop.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <memory>
#include <mutex>
#include <optional>
#include <string>

namespace tessera::drivers {

struct CreateBaseActorOptions {
  std::string device = "/dev/ttyUSB0";
  int baud = 115200;
  std::string frame_id = "base_link";
  double retry_initial_s = 0.5;
  double retry_max_s = 8;
  CreateBaseOptions base;

  template <class V>
  void visit(V& v) {
    v("device", device,
      "serial device of the Create's cable (/dev/ttyUSB0, /dev/serial/by-id/...)");
    v("baud", baud, "the OI's rate: 115200 (Create 2 default) or 19200");
    v("frame_id", frame_id, "frame of wheel_ticks and base_status");
    v("retry_initial_s", retry_initial_s, "[s] first wait before reopening a failed device");
    v("retry_max_s", retry_max_s, "[s] longest wait between reopen attempts (doubling)");
    v("base", base, "geometry, speed limit, watchdog, OI mode");
  }
};

class CreateBaseActor final : public Actor {
 public:
  explicit CreateBaseActor(CreateBaseActorOptions options);  // throws ConfigError
  ~CreateBaseActor() override;

  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  /// frames, bad_frames, commands, watchdog_stops, safety_stops, refused_commands,
  /// garbage_bytes, last_stop_reason, and DeviceLoop's reconnects, open_failures, cpu_s, …
  void summarize(Summary& out) const override;

 private:
  DeviceStep take(BaseOutput&& out);

  CreateBaseActorOptions options_;
  CreateBase base_;
  Publisher<msg::WheelTicks> ticks_pub_;
  Publisher<msg::BaseStatus> status_pub_;
  mutable std::mutex mutex_;  // the command slot and the figures
  struct Command {
    double vx = 0, omega = 0;
  };
  std::optional<Command> pending_;
  CreateBase::Counters counters_;
  std::string last_stop_reason_;
  std::unique_ptr<DeviceLoop> loop_;  // last: its thread uses the members above
};

}  // namespace tessera::drivers
