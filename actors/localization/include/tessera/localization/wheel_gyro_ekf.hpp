// WheelGyroEkf: differential-drive odometry from wheel encoders fused with a gyro by an EKF
// (docs/algorithms.md#wheel-and-gyro-odometry).
//
// State (x, y [m], φ [rad], b [rad/s]): the planar pose in the odometry frame and the gyro's
// bias. Per step, the encoders give the wheel model's rotation θ_w = K1 (Δright − Δleft) and
// distance D = K2/2 (Δright + Δleft) (K2 = metres per tick, K1 = K2 / wheel base); the gyro gives
// the angle it integrated over the step, Δg = θ + b·dt + noise. The step's rotation θ enters the
// filter as a state with prior θ_w (variance (σ_θ θ_w)² + (σ_θd D)²: a standing robot does not
// turn, which is what lets the gyro's bias be learnt at every stop), is corrected by Δg, and the
// pose then moves along the arc (mid-step heading) x += D cos(φ + θ/2), y += D sin(φ + θ/2), φ +=
// θ, with Q_D = (σ_D D)² on the distance and a random walk on the bias. The bias (and through its
// correlation the pose) is corrected at stops only: while the wheels turn those are "consider"
// states (Schmidt-Kalman), because a wheel base a few per cent off would otherwise pass for bias.
// Without a gyro reading the step is the plain wheel model. Units: ticks, metres, radians, seconds.
#pragma once

#include <tessera/geometry/pose2.hpp>

#include <Eigen/Core>

#include <optional>

namespace tessera::localization {

struct WheelGyroEkfOptions {
  double metres_per_tick = 1e-4;  ///< K2
  double wheel_base = 0.3;        ///< [m] distance between the wheels (K1 = K2 / wheel_base)
  double sigma_distance = 0.02;   ///< σ_D: distance noise per metre
  double sigma_rotation = 0.05;   ///< σ_θ: wheel rotation noise per radian
  double sigma_rotation_per_metre = 0.01;  ///< σ_θd [rad/m]: slip when driving straight
  double gyro_noise = 5e-4;                ///< [rad/√s] angle random walk of the gyro
  double gyro_bias_walk = 1e-4;            ///< [rad/s/√s] bias random walk
  double initial_bias_sigma = 0.01;        ///< [rad/s]

  template <class V>
  void visit(V& v) {
    v("metres_per_tick", metres_per_tick, "[m] wheel travel per encoder tick (K2)");
    v("wheel_base", wheel_base, "[m] distance between the wheels");
    v("sigma_distance", sigma_distance, "distance noise per metre travelled");
    v("sigma_rotation", sigma_rotation, "wheel rotation noise per radian turned");
    v("sigma_rotation_per_metre", sigma_rotation_per_metre,
      "[rad/m] wheel rotation noise per metre travelled (slip)");
    v("gyro_noise", gyro_noise, "[rad/sqrt(s)] gyro angle random walk");
    v("gyro_bias_walk", gyro_bias_walk, "[rad/s/sqrt(s)] gyro bias random walk");
    v("initial_bias_sigma", initial_bias_sigma, "[rad/s] prior uncertainty of the gyro bias");
  }
  void validate() const;  ///< throws std::invalid_argument naming the bad field
};

class WheelGyroEkf {
 public:
  explicit WheelGyroEkf(const WheelGyroEkfOptions& options = {}, const Pose2& start = {});

  /// One step of dt seconds: encoder increments [ticks] and, when available, the gyro's
  /// integrated angle over the step [rad]. Returns false (state unchanged) for non-finite input
  /// or dt <= 0.
  bool step(double left_ticks, double right_ticks, double dt,
            std::optional<double> gyro_angle = std::nullopt);

  Pose2 pose() const { return {state_(0), state_(1), state_(2)}; }
  double gyroBias() const { return state_(3); }
  const Eigen::Vector4d& state() const { return state_; }
  const Eigen::Matrix4d& covariance() const { return covariance_; }
  /// Pose covariance over (x, y, φ).
  Eigen::Matrix3d poseCovariance() const { return covariance_.topLeftCorner<3, 3>(); }

 private:
  WheelGyroEkfOptions options_;
  Eigen::Vector4d state_;
  Eigen::Matrix4d covariance_;
};

}  // namespace tessera::localization
