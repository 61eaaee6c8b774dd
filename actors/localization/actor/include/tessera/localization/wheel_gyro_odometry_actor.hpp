// wheel_gyro_odometry actor: differential-drive odometry from wheel encoder ticks, fused with a
// gyro by the WheelGyroEkf (docs/algorithms.md#wheel-and-gyro-odometry).
//
// Subscribes:
//   wheel_ticks  msg::WheelTicks  reliable(ticks_queue): cumulative counts; each message after
//                                 the first is one EKF step over the interval since the last
//   imu          msg::ImuSample   reliable(imu_queue), only with use_gyro: the yaw rate
//                                 (angularVelocityZ), integrated over each step's interval
// Publishes:
//   odom         msg::Odometry    frame "odom", child "base_link", at every step (stamp = the
//                                 ticks' stamp): the EKF pose with its covariance, the step's
//                                 mean forward speed and yaw rate
// Both inputs are reliable: every tick interval and every gyro sample is a piece of the
// integral, and losing one would be a jump in the pose.
//
// Synchronisation: a tick interval waits until gyro samples cover it (the two topics arrive
// independently); if they do not within gyro_timeout_s of newer ticks, it is stepped on the
// wheels alone and counted. stop() steps whatever still waits.
// Calibration: metres per tick = 2π r / ticks_per_revolution and the wheel base come from the
// first message (the driver's nominal numbers) unless calibration_from_message is false, when
// ekf.metres_per_tick and ekf.wheel_base are used (a calibrated robot).
// Bad input is counted by kind in the summary, reported on stderr (the first few of each kind)
// and skipped, never a NaN pose: ticks out of order or at the same stamp, a tick jump no wheel
// can make (counter reset or wrap: the counters re-baseline), an invalid calibration; a NaN or
// out-of-order gyro sample.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/geometry/pose_fields.hpp>
#include <tessera/localization/gyro_buffer.hpp>
#include <tessera/localization/wheel_gyro_ekf.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <string>

namespace tessera::localization {

struct WheelGyroOdometryOptions {
  WheelGyroEkfOptions ekf;
  bool use_gyro = true;
  bool calibration_from_message = true;
  double max_wheel_speed = 5.0;  ///< [m/s] faster tick increments are a counter reset
  double gyro_timeout_s = 0.5;   ///< [s] how long tick intervals wait for gyro samples
  int ticks_queue = 256;
  int imu_queue = 512;
  Pose2 start;  ///< pose of base_link in odom at the first ticks

  template <class V>
  void visit(V& v) {
    v("ekf", ekf,
      "the EKF's noise model; metres_per_tick and wheel_base only with "
      "calibration_from_message: false");
    v("use_gyro", use_gyro, "fuse the gyro (false: wheels alone, for comparison)");
    v("calibration_from_message", calibration_from_message,
      "take metres per tick and wheel base from the wheel_ticks messages (else from ekf)");
    v("max_wheel_speed", max_wheel_speed,
      "[m/s] a wheel moving faster between two messages means a counter reset: re-baseline");
    v("gyro_timeout_s", gyro_timeout_s,
      "[s] a tick interval not covered by gyro samples this long is stepped on wheels alone");
    v("ticks_queue", ticks_queue, "wheel_ticks mailbox capacity (reliable)");
    v("imu_queue", imu_queue, "imu mailbox capacity (reliable)");
    PoseFields start_fields{start};
    v("start", start_fields, "pose of base_link in the odom frame at the first ticks");
  }
};

class WheelGyroOdometryActor final : public Actor {
 public:
  /// Throws ConfigError naming the bad option.
  explicit WheelGyroOdometryActor(WheelGyroOdometryOptions options);

  void configure(ActorContext& ctx) override;
  void stop() override;
  /// ticks_received, imu_received, steps, steps_with_gyro, steps_without_gyro, bad input by
  /// kind (ticks_bad_*, imu_bad_*), calibration_changes, the final pose and gyro bias.
  void summarize(Summary& out) const override;

  /// The filter, once the first valid ticks have arrived.
  const WheelGyroEkf* ekf() const { return ekf_ ? &*ekf_ : nullptr; }

 private:
  struct Interval {
    Nanos t0 = 0, t1 = 0;
    std::int64_t dl = 0, dr = 0;
  };
  void onTicks(const Message<msg::WheelTicks>& m);
  void onImu(const Message<msg::ImuSample>& m);
  /// Steps the waiting intervals that can be stepped (all of them with `flush`).
  void drain(bool flush);
  void stepInterval(const Interval& in, std::optional<double> gyro_angle);
  void bad(std::map<std::string, std::uint64_t>& counts, const std::string& kind,
           const std::string& what);

  WheelGyroOdometryOptions options_;
  std::optional<WheelGyroEkf> ekf_;
  GyroBuffer gyro_;
  std::deque<Interval> waiting_;
  Publisher<msg::Odometry> odom_pub_;

  // The last accepted ticks, and the calibration taken from the first.
  std::optional<Nanos> last_stamp_;
  std::int64_t last_left_ = 0, last_right_ = 0;
  double metres_per_tick_ = 0, wheel_base_ = 0, msg_metres_per_tick_ = 0, msg_wheel_base_ = 0;

  std::uint64_t ticks_received_ = 0, imu_received_ = 0, steps_ = 0, steps_with_gyro_ = 0;
  std::uint64_t steps_without_gyro_ = 0, calibration_changes_ = 0, rejected_steps_ = 0;
  std::map<std::string, std::uint64_t> ticks_bad_, imu_bad_;
};

}  // namespace tessera::localization
