// WheelGyroEkf: the step's rotation as an augmented state, corrected by the gyro, then the arc.
#include <tessera/localization/wheel_gyro_ekf.hpp>

#include <tessera/config/config_check.hpp>

#include <cmath>

namespace tessera::localization {

void WheelGyroEkfOptions::validate() const {
  ConfigCheck()
      .positive("metres_per_tick", metres_per_tick)
      .positive("wheel_base", wheel_base)
      .nonNegative("sigma_distance", sigma_distance)
      .nonNegative("sigma_rotation", sigma_rotation)
      .nonNegative("sigma_rotation_per_metre", sigma_rotation_per_metre)
      .positive("gyro_noise", gyro_noise)
      .nonNegative("gyro_bias_walk", gyro_bias_walk)
      .nonNegative("initial_bias_sigma", initial_bias_sigma)
      .throwIfBad("wheel gyro ekf");
}

WheelGyroEkf::WheelGyroEkf(const WheelGyroEkfOptions& options, const Pose2& start)
    : options_(options) {
  options_.validate();
  state_ << start.x, start.y, start.theta, 0.0;
  covariance_.setZero();
  covariance_(3, 3) = options_.initial_bias_sigma * options_.initial_bias_sigma;
}

bool WheelGyroEkf::step(double left_ticks, double right_ticks, double dt,
                        std::optional<double> gyro_angle) {
  if (!std::isfinite(left_ticks) || !std::isfinite(right_ticks) || !std::isfinite(dt) || dt <= 0 ||
      (gyro_angle && !std::isfinite(*gyro_angle)))
    return false;
  const WheelGyroEkfOptions& o = options_;
  const double k2 = o.metres_per_tick, k1 = k2 / o.wheel_base;
  const double theta_w = k1 * (right_ticks - left_ticks);
  const double distance = k2 / 2 * (right_ticks + left_ticks);

  // Augmented state (x, y, φ, b, θ): θ's prior is the wheels' rotation.
  Eigen::Matrix<double, 5, 1> s;
  s << state_, theta_w;
  Eigen::Matrix<double, 5, 5> p = Eigen::Matrix<double, 5, 5>::Zero();
  p.topLeftCorner<4, 4>() = covariance_;
  // (1e-12 rad² keeps the prior proper when the wheels stand still.)
  p(4, 4) = std::pow(o.sigma_rotation * theta_w, 2) +
            std::pow(o.sigma_rotation_per_metre * distance, 2) + 1e-12;

  if (gyro_angle) {  // z = θ + b·dt, R = σ_g² dt
    Eigen::Matrix<double, 1, 5> h;
    h << 0, 0, 0, dt, 1;
    const double r = o.gyro_noise * o.gyro_noise * dt;
    const double innovation = *gyro_angle - h * s;
    const double sv = (h * p * h.transpose())(0, 0) + r;
    Eigen::Matrix<double, 5, 1> k = p * h.transpose() / sv;
    // While the wheels move, their systematic errors (a wheel base a few per cent off) would
    // pass for gyro bias, and through the heading's correlation with the bias for heading error:
    // only the step's rotation is corrected then, the rest is "considered" (Schmidt-Kalman).
    // At stops the wheels are exact (no rotation) and the full update learns the bias.
    if (theta_w != 0 || distance != 0) k.head<4>().setZero();
    s += k * innovation;
    // Joseph form: valid for the Schmidt gain too, and keeps p symmetric positive semi-definite.
    const Eigen::Matrix<double, 5, 5> a = Eigen::Matrix<double, 5, 5>::Identity() - k * h;
    p = a * p * a.transpose() + k * r * k.transpose();
  }

  const double phi = s(2), theta = s(4), mid = phi + theta / 2;
  const double c = std::cos(mid), sn = std::sin(mid);
  Eigen::Vector4d next;
  next << s(0) + distance * c, s(1) + distance * sn, normalizeAngle(phi + theta), s(3);
  Eigen::Matrix<double, 4, 5> f = Eigen::Matrix<double, 4, 5>::Zero();
  f(0, 0) = 1;
  f(1, 1) = 1;
  f(0, 2) = -distance * sn;
  f(1, 2) = distance * c;
  f(2, 2) = 1;
  f(3, 3) = 1;
  f(0, 4) = -distance * sn / 2;
  f(1, 4) = distance * c / 2;
  f(2, 4) = 1;
  const Eigen::Vector4d g(c, sn, 0, 0);  // ∂/∂D
  Eigen::Matrix4d q = g * g.transpose() * std::pow(o.sigma_distance * distance, 2);
  q(3, 3) += o.gyro_bias_walk * o.gyro_bias_walk * dt;
  covariance_ = f * p * f.transpose() + q;
  covariance_ = 0.5 * (covariance_ + covariance_.transpose());
  state_ = next;
  return true;
}

}  // namespace tessera::localization
