// VectorNavActor ("vectornav"): a VectorNav VN-100 IMU on its serial port, ASCII protocol
// (docs/architecture.md#device-drivers).
//
// Publishes (local topic name):
//   imu  msg::ImuSample  frame frame_id, every VNIMU or VNYMR line (imu.rate_hz): angular rate
//                        [rad/s] and specific force [m/s^2] in REP-103 (x forward, y left, z up;
//                        the VN-100's own y right, z down flipped), stamped when the line began
//                        to arrive; the yaw rate is what wheel_gyro_odometry reads
//
// A DeviceLoop owns the port; the session (VectorNavImu) finds the device at any of its baud
// rates, switches it to `baud`, sets the output and rate, and asks for a reconnect (with
// back-off) when no good sample comes for imu.silence_periods periods. Lines with a bad checksum,
// framing or number (NaN included) are counted by reason and never published. Needs the wall
// clock.
#pragma once

#include <tessera/drivers/device_loop.hpp>
#include <tessera/drivers/vectornav_imu.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <memory>
#include <mutex>
#include <string>

namespace tessera::drivers {

struct VectorNavActorOptions {
  std::string device = "/dev/ttyUSB0";
  int baud = 115200;
  std::string frame_id = "imu";
  double retry_initial_s = 0.5;
  double retry_max_s = 8;
  VectorNavOptions imu;

  template <class V>
  void visit(V& v) {
    v("device", device, "serial device of the VN-100 (/dev/ttyUSB0, /dev/serial/by-id/...)");
    v("baud", baud,
      "session baud rate (9600 .. 921600); the VN-100 is found at whatever rate it is at and "
      "switched");
    v("frame_id", frame_id, "frame of the samples");
    v("retry_initial_s", retry_initial_s, "[s] first wait before reopening a failed device");
    v("retry_max_s", retry_max_s, "[s] longest wait between reopen attempts (doubling)");
    v("imu", imu, "output type and rate, timeouts");
  }
};

class VectorNavActor final : public Actor {
 public:
  explicit VectorNavActor(VectorNavActorOptions options);  // throws ConfigError
  ~VectorNavActor() override;

  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  /// samples, sessions, bad_lines and by reason (truncated, malformed, bad_checksum,
  /// not_finite), device_errors, garbage_bytes, model, and DeviceLoop's reconnects, baud, …
  void summarize(Summary& out) const override;

 private:
  DeviceStep take(ImuOutput&& out);

  VectorNavActorOptions options_;
  VectorNavImu imu_;
  Publisher<msg::ImuSample> pub_;
  mutable std::mutex mutex_;  // the figures
  VectorNavImu::Counters counters_;
  std::string model_;
  std::unique_ptr<DeviceLoop> loop_;  // last: its thread uses the members above
};

}  // namespace tessera::drivers
