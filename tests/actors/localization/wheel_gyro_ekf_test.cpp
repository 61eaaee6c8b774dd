// Tests for the wheel + gyro EKF: steps against hand computation, bias learnt at a stop, and
// heading drift with the gyro against wheels alone on a simulated drive.
#include <tessera/localization/wheel_gyro_ekf.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>
#include <random>

using namespace tessera;
using namespace tessera::localization;

TEST_CASE("a wheel-only step matches the hand-computed arc and covariance", "[localization]") {
  WheelGyroEkfOptions o;  // 1e-4 m/tick, 0.3 m wheel base
  WheelGyroEkf ekf(o);
  REQUIRE(ekf.step(1000, 1500, 0.1));
  // theta = 1e-4 / 0.3 * 500 = 1/6 rad, D = 1e-4 / 2 * 2500 = 0.125 m, along the mid heading.
  const double theta = 1.0 / 6, d = 0.125;
  CHECK(ekf.pose().x == Approx(d * std::cos(theta / 2)));
  CHECK(ekf.pose().y == Approx(d * std::sin(theta / 2)));
  CHECK(ekf.pose().theta == Approx(theta));
  // Var(theta) = (0.05 theta)^2 + (0.01 D)^2; x, y follow through the Jacobian, plus (0.02 D)^2
  // along the heading.
  const double var_theta = std::pow(0.05 * theta, 2) + std::pow(0.01 * d, 2) + 1e-12;
  const double var_d = std::pow(0.02 * d, 2);
  const double c = std::cos(theta / 2), s = std::sin(theta / 2);
  const Eigen::Matrix3d p = ekf.poseCovariance();
  CHECK(p(2, 2) == Approx(var_theta));
  CHECK(p(0, 0) == Approx(d * d * s * s / 4 * var_theta + c * c * var_d));
  CHECK(p(1, 1) == Approx(d * d * c * c / 4 * var_theta + s * s * var_d));
  CHECK(p(0, 2) == Approx(-d * s / 2 * var_theta));
  CHECK(p(1, 2) == Approx(d * c / 2 * var_theta));
}

TEST_CASE("a gyro step weighs the gyro's and the wheels' rotation by their variances",
          "[localization]") {
  WheelGyroEkfOptions o;
  o.initial_bias_sigma = 0;  // bias known to be 0: the update is a plain weighted mean
  WheelGyroEkf ekf(o);
  const double dt = 0.1, gyro = 0.15;
  REQUIRE(ekf.step(1000, 1500, dt, gyro));
  const double theta_w = 1.0 / 6, d = 0.125;
  const double var_w = std::pow(0.05 * theta_w, 2) + std::pow(0.01 * d, 2) + 1e-12;
  const double var_g = o.gyro_noise * o.gyro_noise * dt;
  const double fused = (theta_w / var_w + gyro / var_g) / (1 / var_w + 1 / var_g);
  CHECK(ekf.pose().theta == Approx(fused));
  CHECK(ekf.poseCovariance()(2, 2) == Approx(1 / (1 / var_w + 1 / var_g)));
}

TEST_CASE("the gyro bias is learnt while the robot stands still", "[localization]") {
  WheelGyroEkf ekf;
  for (int i = 0; i < 250; ++i) ekf.step(0, 0, 0.02, 0.004 * 0.02);  // 5 s at 50 Hz, bias 0.004
  CHECK(ekf.gyroBias() == Approx(0.004).margin(2e-4));
  CHECK(std::abs(ekf.pose().theta) < 1e-6);
}

TEST_CASE("heading drifts at least 5x less with the gyro than on wheels alone", "[localization]") {
  // A 5 s stop, then 300 s of driving arcs at 50 Hz. The true wheel base is 2 % off the
  // calibrated one, wheels slip, and the gyro has a 0.003 rad/s bias and noise.
  const double dt = 0.02, true_base = 0.306, mpt = 1e-4;  // calibrated base: 0.3 m
  std::mt19937_64 rng(4);
  std::normal_distribution<double> n01(0.0, 1.0);
  WheelGyroEkf wheels, fused;
  double heading = 0;
  for (int i = 0; i < 15250; ++i) {
    const double t = i * dt;
    const double v = t < 5 ? 0.0 : 0.4, w = t < 5 ? 0.0 : 0.6 * std::sin(0.05 * t);
    const double turn = w * dt + (v > 0 ? 0.002 * n01(rng) * std::sqrt(v * dt) : 0.0);
    heading += turn;
    const double d = v * dt;
    // Ticks that the true geometry produces.
    const double right = (d + turn * true_base / 2) / mpt, left = (d - turn * true_base / 2) / mpt;
    const double gyro = turn + 0.003 * dt + 3e-4 * std::sqrt(dt) * n01(rng);
    wheels.step(left, right, dt);
    fused.step(left, right, dt, gyro);
  }
  const double wheel_error = std::abs(normalizeAngle(wheels.pose().theta - heading));
  const double fused_error = std::abs(normalizeAngle(fused.pose().theta - heading));
  INFO("heading error: wheels " << wheel_error << " rad, with gyro " << fused_error << " rad");
  CHECK(fused_error * 5 < wheel_error);
}

TEST_CASE("the odometry EKF ignores non-finite input", "[localization]") {
  WheelGyroEkf ekf;
  const double nan = std::nan("");
  CHECK_FALSE(ekf.step(nan, 1, 0.1));
  CHECK_FALSE(ekf.step(1, 1, 0));
  CHECK_FALSE(ekf.step(1, 1, 0.1, nan));
  CHECK(ekf.pose().isFinite());
  CHECK(ekf.pose().x == 0);
  WheelGyroEkfOptions o;
  o.wheel_base = -1;
  CHECK_THROWS_WITH(WheelGyroEkf(o), Catch::Contains("wheel_base"));
}
