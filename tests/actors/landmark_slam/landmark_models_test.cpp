// Range-bearing and motion models (Jacobians against finite differences), the unscented
// transform (exact for linear maps, angle-safe) and Mahalanobis gating helpers.
#include <tessera/landmark_slam/landmark_models.hpp>
#include <tessera/landmark_slam/unscented.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Cholesky>

#include <cmath>
#include <functional>
#include <limits>
#include <numbers>

using namespace tessera::landmark_slam;
using namespace tessera;

namespace {

// Central differences of f at x, one column per input; output `angle_row` (if >= 0) is an
// angle whose difference is wrapped.
Eigen::MatrixXd numericJacobian(const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f,
                                const Eigen::VectorXd& x, int angle_row = -1) {
  const double eps = 1e-6;
  const Eigen::VectorXd y0 = f(x);
  Eigen::MatrixXd J(y0.size(), x.size());
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    Eigen::VectorXd a = x, b = x;
    a[i] += eps;
    b[i] -= eps;
    Eigen::VectorXd d = f(a) - f(b);
    if (angle_row >= 0) d[angle_row] = angleDiff(f(a)[angle_row], f(b)[angle_row]);
    J.col(i) = d / (2 * eps);
  }
  return J;
}

}  // namespace

TEST_CASE("range-bearing prediction and its Jacobians match finite differences",
          "[landmark_models]") {
  const Pose2 mount(0.3, -0.1, 0.2);
  const Eigen::Vector3d pose(1.0, -2.0, 2.9);
  const Eigen::Vector2d m(-4.0, 1.5);
  const auto p = predictRangeBearing(pose, m, mount);
  // The sensor sits at pose ⊕ mount.
  const Pose2 s = Pose2(pose[0], pose[1], pose[2]) * mount;
  CHECK(p.z[0] == Approx(std::hypot(m.x() - s.x, m.y() - s.y)));
  CHECK(p.z[1] == Approx(angleDiff(std::atan2(m.y() - s.y, m.x() - s.x), s.theta)));

  Eigen::VectorXd x(5);
  x << pose, m;
  const auto f = [&](const Eigen::VectorXd& a) -> Eigen::VectorXd {
    return predictRangeBearing(a.head<3>(), a.tail<2>(), mount).z;
  };
  const Eigen::MatrixXd J = numericJacobian(f, x, 1);
  CHECK(J.leftCols<3>().isApprox(Eigen::MatrixXd(p.H_pose), 1e-6));
  CHECK(J.rightCols<2>().isApprox(Eigen::MatrixXd(p.H_landmark), 1e-6));
}

TEST_CASE("landmark initialisation inverts the range-bearing model with matching Jacobians",
          "[landmark_models]") {
  const Pose2 mount(0.2, 0.1, -0.3);
  const Eigen::Vector3d pose(3.0, 1.0, -1.2);
  const Eigen::Vector2d z(7.5, 0.6);
  const auto l = landmarkFromRangeBearing(pose, z, mount);
  const auto back = predictRangeBearing(pose, l.m, mount);
  CHECK(back.z[0] == Approx(z[0]));
  CHECK(back.z[1] == Approx(z[1]));

  Eigen::VectorXd x(5);
  x << pose, z;
  const auto f = [&](const Eigen::VectorXd& a) -> Eigen::VectorXd {
    return landmarkFromRangeBearing(a.head<3>(), a.tail<2>(), mount).m;
  };
  const Eigen::MatrixXd J = numericJacobian(f, x);
  CHECK(J.leftCols<3>().isApprox(Eigen::MatrixXd(l.G_pose), 1e-6));
  CHECK(J.rightCols<2>().isApprox(Eigen::MatrixXd(l.G_z), 1e-6));
}

TEST_CASE("drive step Jacobians match finite differences for both drive types",
          "[landmark_models]") {
  for (const double wheelbase : {1.0, 0.0}) {
    INFO("wheelbase " << wheelbase);
    DriveInput u;
    u.speed = 3.0;
    u.steer = 0.2;
    u.turn_rate = -0.4;
    u.wheelbase = wheelbase;
    u.dt = 0.03;
    const Eigen::Vector3d pose(2.0, -1.0, 0.7);
    const MotionStep step = driveStep(pose, u);
    const double heading = wheelbase > 0 ? 0.7 + 0.2 : 0.7;
    CHECK(step.pose[0] == Approx(2.0 + 0.09 * std::cos(heading)));
    CHECK(step.pose[1] == Approx(-1.0 + 0.09 * std::sin(heading)));
    CHECK(step.pose[2] == Approx(wheelbase > 0 ? 0.7 + 0.09 * std::sin(0.2) : 0.7 - 0.012));

    Eigen::VectorXd x(5);
    x << pose, u.speed, wheelbase > 0 ? u.steer : u.turn_rate;
    const auto f = [&](const Eigen::VectorXd& a) -> Eigen::VectorXd {
      DriveInput v = u;
      v.speed = a[3];
      (v.carLike() ? v.steer : v.turn_rate) = a[4];
      return driveStep(a.head<3>(), v).pose;
    };
    const Eigen::MatrixXd J = numericJacobian(f, x);
    CHECK(J.leftCols<3>().isApprox(Eigen::MatrixXd(step.F_pose), 1e-6));
    CHECK(J.rightCols<2>().isApprox(Eigen::MatrixXd(step.F_control), 1e-6));
  }
}

TEST_CASE("unscented transform reproduces a linear map exactly", "[landmark_models][unscented]") {
  Eigen::MatrixXd A(2, 3);
  A << 1.5, -0.3, 2.0, 0.4, 0.9, -1.1;
  const Eigen::Vector2d b(0.5, -2.0);
  const Eigen::Vector3d mean(1.0, -2.0, 0.5);
  Eigen::Matrix3d Lc;
  Lc << 0.5, 0, 0, 0.2, 0.3, 0, -0.1, 0.05, 0.2;
  const Eigen::Matrix3d cov = Lc * Lc.transpose();
  const auto linear = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return A * x + b; };
  for (const UnscentedParams params :
       {UnscentedParams{}, UnscentedParams{0.5, 2.0, 1.0}, UnscentedParams{0.1, 0.0, 0.0}}) {
    INFO("alpha " << params.alpha << " beta " << params.beta << " kappa " << params.kappa);
    const auto r = unscentedTransform(mean, cov, linear, {}, params);
    CHECK((r.mean - (A * mean + b)).norm() < 1e-12);
    CHECK((r.covariance - A * cov * A.transpose()).norm() < 1e-12);
    CHECK((r.cross - cov * A.transpose()).norm() < 1e-12);
  }
  // A singular covariance (one exactly known component) still works.
  Eigen::Matrix3d singular = cov;
  singular.row(2).setZero();
  singular.col(2).setZero();
  const auto r = unscentedTransform(mean, singular, linear);
  CHECK((r.covariance - A * singular * A.transpose()).norm() < 1e-12);
}

TEST_CASE("unscented transform averages angles across the pi wrap",
          "[landmark_models][unscented]") {
  const Eigen::VectorXd mean = Eigen::VectorXd::Constant(1, std::numbers::pi - 0.01);
  const Eigen::MatrixXd cov = Eigen::MatrixXd::Constant(1, 1, 0.05 * 0.05);
  const auto r = unscentedTransform(
      mean, cov, [](const Eigen::VectorXd& x) -> Eigen::VectorXd { return x; }, {0});
  CHECK(std::abs(angleDiff(r.mean[0], std::numbers::pi - 0.01)) < 1e-12);
  CHECK(r.covariance(0, 0) == Approx(0.05 * 0.05));
}

TEST_CASE("unscented transform rejects an indefinite covariance", "[landmark_models][unscented]") {
  Eigen::Matrix2d cov;
  cov << 1, 2, 2, 1;
  CHECK_THROWS_AS(unscentedTransform(Eigen::Vector2d::Zero(), cov,
                                     [](const Eigen::VectorXd& x) -> Eigen::VectorXd { return x; }),
                  std::invalid_argument);
}

TEST_CASE("mahalanobis distance and chi-square gates", "[landmark_models]") {
  Eigen::Matrix2d S;
  S << 4, 0, 0, 0.25;
  CHECK(mahalanobis2({2, 0.5}, S) == Approx(2.0));
  Eigen::Matrix2d bad;
  bad << 1, 0, 0, -1;
  CHECK(std::isinf(mahalanobis2({1, 1}, bad)));
  CHECK(chiSquare2(0.99) == Approx(9.2103).epsilon(1e-4));
  CHECK(chiSquare2(0.95) == Approx(5.9915).epsilon(1e-4));
}
