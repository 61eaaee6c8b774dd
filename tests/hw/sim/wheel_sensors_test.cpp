// The simulated gyro (bias, white noise, bias walk) and wheel encoders (calibration errors,
// slip, quantisation to ticks).
#include <tessera/sim/wheel_sensors.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

using namespace tessera::sim;

namespace {

struct Stats {
  double mean = 0, std = 0;
};
Stats stats(const std::vector<double>& v) {
  double s = 0, s2 = 0;
  for (double x : v) s += x;
  const double mean = s / static_cast<double>(v.size());
  for (double x : v) s2 += (x - mean) * (x - mean);
  return {mean, std::sqrt(s2 / static_cast<double>(v.size() - 1))};
}

}  // namespace

TEST_CASE("Gyro: samples carry the bias and white noise of the configured density", "[sim][gyro]") {
  GyroOptions o;
  o.bias = 0.003;
  o.bias_walk = 0;
  o.noise_density = 2.5e-4;
  Gyro gyro(o);
  std::mt19937_64 rng(7);
  const double dt = 0.01;
  std::vector<double> z, x, ax, az;
  for (int i = 0; i < 20000; ++i) {
    // Turning at 0.4 rad/s while accelerating at 0.5 m/s^2.
    const ImuReading r = gyro.sample(0.4 * dt, 0.1, 0.1 + 0.5 * dt, 0.2, dt, rng);
    z.push_back(r.angular_velocity.z());
    x.push_back(r.angular_velocity.x());
    ax.push_back(r.linear_acceleration.x());
    az.push_back(r.linear_acceleration.z());
  }
  const double rate_std = 2.5e-4 / std::sqrt(dt);  // 2.5e-3 rad/s
  const Stats sz = stats(z), sx = stats(x);
  // Standard error of the mean: 2.5e-3 / sqrt(20000) = 1.8e-5.
  CHECK(sz.mean == Approx(0.4 + 0.003).margin(1e-4));
  CHECK(sz.std == Approx(rate_std).epsilon(0.03));
  CHECK(sx.mean == Approx(0).margin(1e-4));
  CHECK(sx.std == Approx(rate_std).epsilon(0.03));
  CHECK(stats(ax).mean == Approx(0.5).margin(1e-3));
  CHECK(stats(az).mean == Approx(9.80665).margin(1e-3));
  CHECK(gyro.bias() == 0.003);  // no walk
}

TEST_CASE("Gyro: the bias random-walks with the configured density", "[sim][gyro]") {
  GyroOptions o;
  o.bias = -0.002;
  o.bias_walk = 1e-4;
  o.noise_density = 0;
  const double dt = 0.01;
  const int steps = 1000;  // 10 s: std of the walk 1e-4 * sqrt(10)
  std::vector<double> final_bias;
  for (std::uint64_t seed = 0; seed < 400; ++seed) {
    Gyro gyro(o);
    std::mt19937_64 rng(seed);
    for (int i = 0; i < steps; ++i) {
      // Without white noise a sample is the rate plus the bias it was drawn with.
      const double bias = gyro.bias();
      REQUIRE(gyro.sample(0, 0, 0, 0, dt, rng).angular_velocity.z() == bias);
    }
    final_bias.push_back(gyro.bias());
  }
  const Stats s = stats(final_bias);
  CHECK(s.mean == Approx(-0.002).margin(3 * 1e-4 * std::sqrt(10.0) / std::sqrt(400.0)));
  CHECK(s.std == Approx(1e-4 * std::sqrt(10.0)).epsilon(0.12));
}

TEST_CASE("WheelEncoders: ticks are the floor of the true wheel angle", "[sim][encoders]") {
  EncoderOptions o;
  o.ticks_per_revolution = 1000;
  o.wheel_radius = 0.05;
  o.wheel_base = 0.4;
  o.left_radius_error = o.right_radius_error = o.wheel_base_error = o.slip = 0;
  WheelEncoders enc(o);
  std::mt19937_64 rng(1);
  const double per_metre = 1000 / (2 * std::numbers::pi * 0.05);  // 3183.1 ticks/m
  enc.move(0.0001, 0, rng);  // 0.318 ticks: not a whole tick yet
  CHECK(enc.leftTicks() == 0);
  CHECK(enc.rightTicks() == 0);
  for (int i = 0; i < 9999; ++i) enc.move(0.0001, 0, rng);  // 1 m in all
  CHECK(enc.leftExact() == Approx(per_metre));
  CHECK(enc.leftTicks() == 3183);
  CHECK(enc.rightTicks() == 3183);
  // Turning in place by pi/2: each wheel rolls pi/2 * 0.2 m, the left one backwards.
  enc.move(0, std::numbers::pi / 2, rng);
  const double roll = std::numbers::pi / 2 * 0.2 * per_metre;  // 1000 ticks
  CHECK(enc.rightExact() == Approx(per_metre + roll));
  CHECK(enc.leftExact() == Approx(per_metre - roll));
  CHECK(enc.leftTicks() == static_cast<std::int64_t>(std::floor(per_metre - roll)));
  // Backwards past zero: floor, not truncation.
  enc.move(-(per_metre - roll + 0.5) / per_metre, 0, rng);
  CHECK(enc.leftTicks() == -1);
}

TEST_CASE("WheelEncoders: calibration errors and slip", "[sim][encoders]") {
  EncoderOptions o;
  o.slip = 0;
  o.left_radius_error = 0.01;
  o.right_radius_error = -0.01;
  o.wheel_base_error = 0.05;
  std::mt19937_64 rng(3);
  {
    WheelEncoders enc(o);
    enc.move(1.0, 0, rng);
    const double nominal = o.ticks_per_revolution / (2 * std::numbers::pi * o.wheel_radius);
    // A larger wheel turns less for the same travel.
    CHECK(enc.leftExact() == Approx(nominal / 1.01));
    CHECK(enc.rightExact() == Approx(nominal / 0.99));
  }
  {
    o.left_radius_error = o.right_radius_error = 0;
    WheelEncoders enc(o);
    enc.move(0, 1.0, rng);  // the true wheel base is 5 % wider: each wheel rolls 5 % more
    const double nominal = o.ticks_per_revolution / (2 * std::numbers::pi * o.wheel_radius);
    CHECK(enc.rightExact() == Approx(o.wheel_base * 1.05 / 2 * nominal));
  }
  {
    o.wheel_base_error = 0;
    o.slip = 0.02;
    std::vector<double> rel;
    for (int i = 0; i < 5000; ++i) {
      WheelEncoders enc(o);
      enc.move(0.01, 0, rng);
      const double nominal = 0.01 * o.ticks_per_revolution / (2 * std::numbers::pi * 0.05);
      rel.push_back(enc.leftExact() / nominal - 1);
    }
    const Stats s = stats(rel);
    CHECK(s.mean == Approx(0).margin(0.002));
    CHECK(s.std == Approx(0.02).epsilon(0.05));
  }
}

TEST_CASE("Gyro and encoder options: bad values are named", "[sim][gyro][encoders]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  GyroOptions g;
  g.noise_density = -1;
  CHECK(g.check().problem()->key == "noise_density");
  g = {};
  g.bias = nan;
  CHECK(g.check().problem()->key == "bias");
  EncoderOptions e;
  e.ticks_per_revolution = 0;
  CHECK(e.check().problem()->key == "ticks_per_revolution");
  e = {};
  e.left_radius_error = 0.5;
  CHECK(e.check().problem()->key == "left_radius_error");
  e = {};
  e.slip = nan;
  CHECK(e.check().problem()->key == "slip");
  CHECK_FALSE(GyroOptions{}.check().problem());
  CHECK_FALSE(EncoderOptions{}.check().problem());
}
