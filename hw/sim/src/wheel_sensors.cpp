#include <tessera/sim/wheel_sensors.hpp>

#include <cmath>
#include <numbers>

namespace tessera::sim {

namespace {
constexpr double kGravity = 9.80665;  // [m/s²]
}  // namespace

ConfigCheck GyroOptions::check() const {
  ConfigCheck c;
  c.nonNegative("noise_density", noise_density).nonNegative("bias_walk", bias_walk);
  c.require(std::isfinite(bias) && std::abs(bias) < 1.0, "bias",
            "must be finite and within (-1, 1) rad/s", bias);
  c.nonNegative("accel_noise_density", accel_noise_density);
  return c;
}

Gyro::Gyro(const GyroOptions& options) : options_(options), bias_(options.bias) {}

ImuReading Gyro::sample(double rotation, double v0, double v1, double centripetal, double dt,
                        std::mt19937_64& rng) {
  // Every normal is drawn on each call, so the stream does not depend on the motion.
  std::normal_distribution<double> normal(0.0, 1.0);
  ImuReading r;
  const double rate_std = options_.noise_density / std::sqrt(dt);
  const double accel_std = options_.accel_noise_density / std::sqrt(dt);
  r.angular_velocity.x() = rate_std * normal(rng);
  r.angular_velocity.y() = rate_std * normal(rng);
  r.angular_velocity.z() = rotation / dt + bias_ + rate_std * normal(rng);
  r.linear_acceleration.x() = (v1 - v0) / dt + accel_std * normal(rng);
  r.linear_acceleration.y() = centripetal + accel_std * normal(rng);
  r.linear_acceleration.z() = kGravity + accel_std * normal(rng);
  bias_ += options_.bias_walk * std::sqrt(dt) * normal(rng);
  return r;
}

ConfigCheck EncoderOptions::check() const {
  ConfigCheck c;
  c.positive("ticks_per_revolution", ticks_per_revolution);
  c.positive("wheel_radius", wheel_radius).positive("wheel_base", wheel_base);
  for (const auto& [key, value] :
       {std::pair<const char*, double>{"left_radius_error", left_radius_error},
        {"right_radius_error", right_radius_error},
        {"wheel_base_error", wheel_base_error}})
    c.require(std::isfinite(value) && std::abs(value) < 0.2, key,
              "must be finite and within (-0.2, 0.2)", value);
  c.require(std::isfinite(slip) && slip >= 0 && slip <= 0.5, "slip", "must be in [0, 0.5]", slip);
  return c;
}

WheelEncoders::WheelEncoders(const EncoderOptions& options) : options_(options) {}

void WheelEncoders::move(double distance, double rotation, std::mt19937_64& rng) {
  const EncoderOptions& o = options_;
  const double base = o.wheel_base * (1 + o.wheel_base_error);
  const double left = distance - rotation * base / 2, right = distance + rotation * base / 2;
  std::normal_distribution<double> normal(0.0, 1.0);
  const double zl = normal(rng), zr = normal(rng);  // always both: a motion-independent stream
  const double left_slipped = left + o.slip * std::abs(left) * zl;
  const double right_slipped = right + o.slip * std::abs(right) * zr;
  const double ticks_per_radian = o.ticks_per_revolution / (2 * std::numbers::pi);
  left_ += left_slipped / (o.wheel_radius * (1 + o.left_radius_error)) * ticks_per_radian;
  right_ += right_slipped / (o.wheel_radius * (1 + o.right_radius_error)) * ticks_per_radian;
}

std::int64_t WheelEncoders::leftTicks() const {
  return static_cast<std::int64_t>(std::floor(left_));
}
std::int64_t WheelEncoders::rightTicks() const {
  return static_cast<std::int64_t>(std::floor(right_));
}

}  // namespace tessera::sim
