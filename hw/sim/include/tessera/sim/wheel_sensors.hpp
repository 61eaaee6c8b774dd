// Simulated proprioceptive sensors of a differential-drive base: a gyro (with the accelerometer
// of the same IMU) and the two wheel encoders (docs/algorithms.md#simulated-motion-and-sensors).
//
// Gyro: each sample is the mean yaw rate over the interval since the previous sample, as an
// integrating MEMS gyro reports it: true mean rate + bias + white noise of density σ_g
// [rad/s/√Hz] (std σ_g / √interval). The bias starts at `bias` and random-walks by
// N(0, σ_b² · interval) per sample. Roll and pitch rates are noise only (a planar robot).
// Accelerometer: the body's specific force, forward dv/dt, lateral v·ω, gravity on z, each
// with white noise of density accel_noise_density.
//
// Encoders: the true wheels differ from the nominal calibration a user configures (radius
// errors per wheel, wheel base error), so ticks integrated with the nominal numbers drift as
// real odometry does; each wheel's travel per step also slips by N(0, (slip · |travel|)²).
// Ticks are the floor of the cumulative wheel angle in ticks: quantised, as a counter is.
// Units: metres, radians, seconds, ticks. Deterministic given the std::mt19937_64 passed in.
#pragma once

#include <tessera/sim/config_check.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <random>

namespace tessera::sim {

struct GyroOptions {
  bool enabled = false;           ///< publish imu samples
  int rate_hz = 100;              ///< [Hz] sample rate; must divide the simulator's step_hz
  double noise_density = 2.5e-4;  ///< σ_g [rad/s/√Hz] (≈ 0.014 °/s/√Hz, a good MEMS gyro)
  double bias = 0.003;            ///< [rad/s] yaw-rate bias at the start (≈ 0.17 °/s)
  double bias_walk = 1e-5;        ///< σ_b [rad/s/√s] random walk of the bias
  double accel_noise_density = 2e-3;  ///< [m/s²/√Hz] accelerometer white noise

  template <class V>
  void visit(V& v) {
    v("enabled", enabled, "publish imu samples (gyro and accelerometer) on 'imu'");
    v("rate_hz", rate_hz, "sample rate [Hz]; must divide step_hz");
    v("noise_density", noise_density, "gyro white noise density [rad/s/sqrt(Hz)]");
    v("bias", bias, "yaw-rate bias at the start [rad/s]");
    v("bias_walk", bias_walk, "random walk of the gyro bias [rad/s/sqrt(s)]");
    v("accel_noise_density", accel_noise_density,
      "accelerometer white noise density [m/s^2/sqrt(Hz)]");
  }
  /// Noise densities and walk >= 0, bias finite with |bias| < 1 rad/s (rate_hz is the
  /// simulator's to check against step_hz).
  ConfigCheck check() const;
};

/// One IMU sample: rates [rad/s] and specific force [m/s²] in base_link (x fwd, y left, z up).
struct ImuReading {
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d linear_acceleration = Eigen::Vector3d::Zero();
};

class Gyro {
 public:
  explicit Gyro(const GyroOptions& options);

  /// The sample that ends an interval of `dt` seconds over which the body turned by `rotation`
  /// [rad] and its forward speed went from v0 to v1 [m/s] with mean v·ω `centripetal` [m/s²].
  /// Draws the noise, then advances the bias by its random walk over dt.
  ImuReading sample(double rotation, double v0, double v1, double centripetal, double dt,
                    std::mt19937_64& rng);
  /// The bias the next sample will carry [rad/s].
  double bias() const { return bias_; }

 private:
  GyroOptions options_;
  double bias_;
};

struct EncoderOptions {
  bool enabled = false;                ///< publish wheel_ticks
  int rate_hz = 50;                    ///< [Hz]; must divide the simulator's step_hz
  double ticks_per_revolution = 4096;  ///< encoder resolution
  double wheel_radius = 0.05;          ///< [m] nominal radius (what the driver reports)
  double wheel_base = 0.35;            ///< [m] nominal distance between the wheels
  double left_radius_error = 0.006;    ///< true left radius = nominal × (1 + this)
  double right_radius_error = 0.004;   ///< true right radius = nominal × (1 + this)
  double wheel_base_error = 0.01;      ///< true wheel base = nominal × (1 + this)
  double slip = 0.01;                  ///< slip std per step, relative to the wheel's travel

  template <class V>
  void visit(V& v) {
    v("enabled", enabled, "publish cumulative encoder ticks on 'wheel_ticks'");
    v("rate_hz", rate_hz, "tick message rate [Hz]; must divide step_hz");
    v("ticks_per_revolution", ticks_per_revolution, "encoder ticks per wheel revolution");
    v("wheel_radius", wheel_radius, "nominal wheel radius reported with the ticks [m]");
    v("wheel_base", wheel_base, "nominal wheel base reported with the ticks [m]");
    v("left_radius_error", left_radius_error,
      "true left wheel radius = nominal * (1 + this): a calibration error");
    v("right_radius_error", right_radius_error,
      "true right wheel radius = nominal * (1 + this): a calibration error");
    v("wheel_base_error", wheel_base_error, "true wheel base = nominal * (1 + this)");
    v("slip", slip, "wheel slip: std per step relative to that wheel's travel in the step");
  }
  /// Positive resolution and geometry; errors finite within (-0.2, 0.2); slip in [0, 0.5].
  ConfigCheck check() const;
};

class WheelEncoders {
 public:
  explicit WheelEncoders(const EncoderOptions& options);

  /// The body moved `distance` [m] while turning by `rotation` [rad] in one step: each true
  /// wheel rolls its share, slips, and its counter advances.
  void move(double distance, double rotation, std::mt19937_64& rng);

  /// Cumulative ticks (floor of the wheel angle in ticks).
  std::int64_t leftTicks() const;
  std::int64_t rightTicks() const;
  /// Wheel angles in ticks before quantisation (for tests).
  double leftExact() const { return left_; }
  double rightExact() const { return right_; }
  const EncoderOptions& options() const { return options_; }

 private:
  EncoderOptions options_;
  double left_ = 0, right_ = 0;  // cumulative wheel angle [ticks]
};

}  // namespace tessera::sim
