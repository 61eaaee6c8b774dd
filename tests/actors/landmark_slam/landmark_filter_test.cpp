// EkfSlam and RbUkfSlam on a 3-landmark toy problem against an update computed here
// independently (plain formulas, finite-difference Jacobians, hand-written sigma points), plus
// rejection of malformed observations and nearest-neighbour association.
#include <tessera/landmark_slam/landmark_filter.hpp>

#include <catch2/catch.hpp>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <vector>

using namespace tessera;
using namespace tessera::landmark_slam;
using Eigen::MatrixXd;
using Eigen::VectorXd;

namespace {

constexpr double kDeg = std::numbers::pi / 180;

double wrap(double a) {
  return std::atan2(std::sin(a), std::cos(a));
}

// The models written out again, independently of tessera/landmark_slam/landmark_models.
VectorXd hPlain(const VectorXd& pose, const VectorXd& m) {
  const double dx = m[0] - pose[0], dy = m[1] - pose[1];
  return Eigen::Vector2d(std::sqrt(dx * dx + dy * dy), wrap(std::atan2(dy, dx) - pose[2]));
}
VectorXd gPlain(const VectorXd& pose, const VectorXd& z) {
  return Eigen::Vector2d(pose[0] + z[0] * std::cos(pose[2] + z[1]),
                         pose[1] + z[0] * std::sin(pose[2] + z[1]));
}
VectorXd fPlain(const VectorXd& pose, double v, double gamma, double L, double dt) {
  return Eigen::Vector3d(pose[0] + dt * v * std::cos(pose[2] + gamma),
                         pose[1] + dt * v * std::sin(pose[2] + gamma),
                         pose[2] + dt * v * std::sin(gamma) / L);
}

MatrixXd jac(const std::function<VectorXd(const VectorXd&)>& f, const VectorXd& x) {
  const double eps = 1e-6;
  MatrixXd J(f(x).size(), x.size());
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    VectorXd a = x, b = x;
    a[i] += eps;
    b[i] -= eps;
    VectorXd d = f(a) - f(b);
    if (d.size() == 2) d[1] = wrap(d[1]);  // the bearing row of h
    J.col(i) = d / (2 * eps);
  }
  return J;
}

struct Toy {
  LandmarkSlamOptions options;
  Eigen::Vector3d pose0{1.0, 2.0, 0.3};
  std::vector<Eigen::Vector2d> truth{{6, 3}, {4, 8}, {-2, 5}};
  double v = 2.0, gamma = 0.1, L = 1.0, dt = 0.5;
  Eigen::Vector3d pose1_true{1.95, 2.32, 0.38};  // where the robot really went
  Eigen::Matrix2d R;
  Toy() {
    options.initial_pose = {pose0[0], pose0[1], pose0[2]};
    options.initial_std = {0.1, 0.1, 0.05};
    options.range_std = 0.1;
    options.bearing_std = 1 * kDeg;
    options.use_observation_std = false;
    options.sigma_speed = 0.3;
    options.sigma_steer = 3 * kDeg;
    options.outlier_gate = 0;
    R = Eigen::Vector2d(0.01, kDeg * kDeg).asDiagonal();
  }
  // Sightings with fixed "noise" so the updates move things.
  std::vector<Observation> first() const {
    std::vector<Observation> out;
    for (int i = 0; i < 3; ++i) {
      const VectorXd z = hPlain(pose0, truth[i]);
      out.push_back({10 + i, z[0] + 0.03 * (i - 1), z[1] + 0.004 * (1 - i)});
    }
    return out;
  }
  std::vector<Observation> second() const {
    std::vector<Observation> out;
    for (int i = 0; i < 3; ++i) {
      const VectorXd z = hPlain(pose1_true, truth[i]);
      out.push_back({10 + i, z[0] - 0.05 + 0.02 * i, z[1] + 0.006 * (i - 1)});
    }
    return out;
  }
  tessera::landmark_slam::DriveInput control() const {
    tessera::landmark_slam::DriveInput u;
    u.speed = v;
    u.steer = gamma;
    u.wheelbase = L;
    u.dt = dt;
    return u;
  }
  Eigen::Matrix2d M() const { return Eigen::Vector2d(0.09, 9 * kDeg * kDeg).asDiagonal(); }
};

VectorXd zOf(const Observation& o) {
  return Eigen::Vector2d(o.range, o.bearing);
}

}  // namespace

TEST_CASE("EKF-SLAM matches a hand-computed joint EKF on 3 landmarks", "[landmark_slam]") {
  const Toy toy;
  EkfSlam ekf(toy.options);
  const auto first = toy.first(), second = toy.second();
  REQUIRE(ekf.update(first).added == 3);
  ekf.predict(toy.control());
  REQUIRE(ekf.update(second).corrected == 3);

  // Independent joint EKF.
  VectorXd x = toy.pose0;
  MatrixXd P = Eigen::Vector3d(0.01, 0.01, 0.0025).asDiagonal();
  for (const auto& o : first) {
    const VectorXd pose = x.head(3), z = zOf(o);
    const MatrixXd Gr = jac([&](const VectorXd& p) { return gPlain(p, z); }, pose);
    const MatrixXd Gz = jac([&](const VectorXd& zz) { return gPlain(pose, zz); }, z);
    const Eigen::Index n = x.size();
    x.conservativeResize(n + 2);
    x.tail(2) = gPlain(pose, z);
    MatrixXd Pn = MatrixXd::Zero(n + 2, n + 2);
    Pn.topLeftCorner(n, n) = P;
    Pn.block(n, 0, 2, n) = Gr * P.topRows(3);
    Pn.block(0, n, n, 2) = Pn.block(n, 0, 2, n).transpose();
    Pn.block(n, n, 2, 2) =
        Gr * P.topLeftCorner(3, 3) * Gr.transpose() + Gz * toy.R * Gz.transpose();
    P = Pn;
  }
  {
    const VectorXd pose = x.head(3);
    const MatrixXd F =
        jac([&](const VectorXd& p) { return fPlain(p, toy.v, toy.gamma, toy.L, toy.dt); }, pose);
    const MatrixXd Fu =
        jac([&](const VectorXd& u) { return fPlain(pose, u[0], u[1], toy.L, toy.dt); },
            Eigen::Vector2d(toy.v, toy.gamma));
    MatrixXd Fx = MatrixXd::Identity(x.size(), x.size());
    Fx.topLeftCorner(3, 3) = F;
    x.head(3) = fPlain(pose, toy.v, toy.gamma, toy.L, toy.dt);
    MatrixXd Q = MatrixXd::Zero(x.size(), x.size());
    Q.topLeftCorner(3, 3) = Fu * toy.M() * Fu.transpose();
    P = Fx * P * Fx.transpose() + Q;
  }
  for (int i = 0; i < 3; ++i) {
    const auto h = [&](const VectorXd& s) { return hPlain(s.head(3), s.segment(3 + 2 * i, 2)); };
    const MatrixXd H = jac(h, x);
    const MatrixXd S = H * P * H.transpose() + toy.R;
    const MatrixXd K = P * H.transpose() * S.inverse();
    VectorXd nu = zOf(second[i]) - h(x);
    nu[1] = wrap(nu[1]);
    x += K * nu;
    P = (MatrixXd::Identity(x.size(), x.size()) - K * H) * P;
  }

  const VectorXd got = ekf.state();
  REQUIRE(got.size() == 9);
  CHECK((got - x).cwiseAbs().maxCoeff() < 1e-7);
  CHECK((ekf.covariance() - P).cwiseAbs().maxCoeff() < 1e-8);
  // The correction moved the pose towards the truth.
  CHECK((got.head<2>() - toy.pose1_true.head<2>()).norm() <
        (fPlain(toy.pose0, toy.v, toy.gamma, toy.L, toy.dt).head(2) - toy.pose1_true.head<2>())
            .norm());
  CHECK(ekf.landmark(1).id == 11);
}

namespace {

// Scaled unscented transform with alpha = 1, beta = 2, kappa = 0 (the defaults), by hand.
struct Ut {
  VectorXd mean;
  MatrixXd cov, cross;
};
Ut handUt(const VectorXd& mu, const MatrixXd& C,
          const std::function<VectorXd(const VectorXd&)>& f) {
  const int n = static_cast<int>(mu.size());
  const MatrixXd Lc = Eigen::LLT<MatrixXd>(C).matrixL();
  std::vector<VectorXd> X{mu};
  for (int i = 0; i < n; ++i) X.push_back(mu + std::sqrt(double(n)) * Lc.col(i));
  for (int i = 0; i < n; ++i) X.push_back(mu - std::sqrt(double(n)) * Lc.col(i));
  // lambda = 0: the central point has mean weight 0 and covariance weight 2.
  std::vector<double> wm(2 * n + 1, 1.0 / (2 * n)), wc = wm;
  wm[0] = 0;
  wc[0] = 2;
  std::vector<VectorXd> Y;
  for (const auto& p : X) Y.push_back(f(p));
  Ut r;
  r.mean = VectorXd::Zero(Y[0].size());
  for (int i = 0; i <= 2 * n; ++i) r.mean += wm[i] * Y[i];
  r.cov = MatrixXd::Zero(Y[0].size(), Y[0].size());
  r.cross = MatrixXd::Zero(n, Y[0].size());
  for (int i = 0; i <= 2 * n; ++i) {
    r.cov += wc[i] * (Y[i] - r.mean) * (Y[i] - r.mean).transpose();
    r.cross += wc[i] * (X[i] - mu) * (Y[i] - r.mean).transpose();
  }
  return r;
}

}  // namespace

TEST_CASE("Rao-Blackwellised filter matches a hand-computed UKF pose and 2x2 EKF landmarks",
          "[landmark_slam]") {
  const Toy toy;
  RbUkfSlam rb(toy.options);
  const auto first = toy.first(), second = toy.second();
  REQUIRE(rb.update(first).added == 3);
  rb.predict(toy.control());
  REQUIRE(rb.update(second).corrected == 3);

  VectorXd pose = toy.pose0;
  MatrixXd P = Eigen::Vector3d(0.01, 0.01, 0.0025).asDiagonal();
  std::vector<VectorXd> m;
  std::vector<MatrixXd> Pm;
  for (const auto& o : first) {
    const VectorXd z = zOf(o);
    const MatrixXd Gr = jac([&](const VectorXd& p) { return gPlain(p, z); }, pose);
    const MatrixXd Gz = jac([&](const VectorXd& zz) { return gPlain(pose, zz); }, z);
    m.push_back(gPlain(pose, z));
    Pm.push_back(Gr * P * Gr.transpose() + Gz * toy.R * Gz.transpose());
  }
  {
    VectorXd mu = VectorXd::Zero(5);
    mu.head(3) = pose;
    MatrixXd C = MatrixXd::Zero(5, 5);
    C.topLeftCorner(3, 3) = P;
    C.bottomRightCorner(2, 2) = toy.M();
    const Ut r = handUt(mu, C, [&](const VectorXd& a) {
      return fPlain(a.head(3), toy.v + a[3], toy.gamma + a[4], toy.L, toy.dt);
    });
    pose = r.mean;
    P = r.cov;
  }
  for (int i = 0; i < 3; ++i) {
    VectorXd mu(5);
    mu << pose, m[i];
    MatrixXd C = MatrixXd::Zero(5, 5);
    C.topLeftCorner(3, 3) = P;
    C.bottomRightCorner(2, 2) = Pm[i];
    const Ut r = handUt(mu, C, [](const VectorXd& a) { return hPlain(a.head(3), a.tail(2)); });
    const MatrixXd S = r.cov + toy.R;
    VectorXd nu = zOf(second[i]) - r.mean;
    nu[1] = wrap(nu[1]);
    const MatrixXd Kx = r.cross.topRows(3) * S.inverse();
    // The landmark's own EKF at the prior pose, pose uncertainty as extra noise.
    const MatrixXd Hm = jac([&](const VectorXd& l) { return hPlain(pose, l); }, m[i]);
    const MatrixXd Hx = jac([&](const VectorXd& p) { return hPlain(p, m[i]); }, pose);
    const MatrixXd Sm = Hm * Pm[i] * Hm.transpose() + Hx * P * Hx.transpose() + toy.R;
    const MatrixXd Km = Pm[i] * Hm.transpose() * Sm.inverse();
    VectorXd nu_m = zOf(second[i]) - hPlain(pose, m[i]);
    nu_m[1] = wrap(nu_m[1]);
    pose += Kx * nu;
    P -= Kx * S * Kx.transpose();
    m[i] += Km * nu_m;
    Pm[i] -= Km * Sm * Km.transpose();
  }

  CHECK((rb.pose() - pose).cwiseAbs().maxCoeff() < 1e-9);
  CHECK((rb.poseCovariance() - P).cwiseAbs().maxCoeff() < 1e-10);
  for (int i = 0; i < 3; ++i) {
    INFO("landmark " << i);
    const auto l = rb.landmark(static_cast<std::size_t>(i));
    CHECK(l.id == 10 + i);
    CHECK((l.mean - m[i]).cwiseAbs().maxCoeff() < 1e-7);
    CHECK((l.covariance - Pm[i]).cwiseAbs().maxCoeff() < 1e-8);
  }

  // Both filters see the same toy problem; with small uncertainties they nearly agree.
  EkfSlam ekf(toy.options);
  ekf.update(first);
  ekf.predict(toy.control());
  ekf.update(second);
  CHECK((ekf.pose().head<2>() - rb.pose().head<2>()).norm() < 0.02);
  CHECK(std::abs(ekf.pose()[2] - rb.pose()[2]) < 0.01);
}

TEST_CASE("malformed observations are rejected with a counted reason", "[landmark_slam]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const bool rb : {false, true}) {
    INFO((rb ? "rbekf" : "ekf"));
    LandmarkSlamOptions o;
    std::unique_ptr<LandmarkFilter> f;
    if (rb)
      f = std::make_unique<RbUkfSlam>(o);
    else
      f = std::make_unique<EkfSlam>(o);
    const std::vector<Observation> bad{
        {1, nan, 0.1},  {2, 5.0, std::numeric_limits<double>::infinity()},
        {3, -1.0, 0.2}, {4, 0.0, 0.2},
        {-1, 5.0, 0.3}, {5, 4.0, 0.5, nan, 0}};
    const auto r = f->update(bad);
    CHECK(r.added == 0);
    CHECK(r.rejected == bad.size());
    CHECK(f->rejections().non_finite == 3);
    CHECK(f->rejections().negative_range == 2);
    CHECK(f->rejections().unknown_id == 1);
    CHECK(f->landmarkCount() == 0);
    CHECK(f->pose().isZero());

    // A known landmark seen 20 m away from where the map has it fails the gate.
    const std::vector<Observation> good{{7, 10.0, 0.0}};
    f->update(good);
    const std::vector<Observation> wild{{7, 30.0, 0.0}, {7, 10.0, 0.0}};
    const auto w = f->update(wild);
    CHECK(f->rejections().gate == 1);
    CHECK(w.corrected == 1);
    // The same id twice in one scan: the second is a duplicate.
    const std::vector<Observation> twice{{7, 10.0, 0.0}, {7, 10.01, 0.0}};
    f->update(twice);
    CHECK(f->rejections().duplicate == 1);

    tessera::landmark_slam::DriveInput u;
    u.speed = nan;
    u.dt = 0.1;
    f->predict(u);
    u.speed = 1;
    u.dt = -1;
    f->predict(u);
    CHECK(f->rejections().bad_control == 2);
    CHECK(f->pose().allFinite());
  }
}

TEST_CASE("nearest-neighbour association matches, adds, and drops ambiguous sightings",
          "[landmark_slam]") {
  for (const bool rb : {false, true}) {
    INFO((rb ? "rbekf" : "ekf"));
    LandmarkSlamOptions o;
    o.association = Association::kNearestNeighbour;
    o.initial_std = {0.01, 0.01, 0.001};
    std::unique_ptr<LandmarkFilter> f;
    if (rb)
      f = std::make_unique<RbUkfSlam>(o);
    else
      f = std::make_unique<EkfSlam>(o);
    // Two landmarks far apart (ids ignored: -1), then two close together.
    const std::vector<Observation> init{{-1, 10.0, 0.5}, {-1, 10.0, -0.5}};
    CHECK(f->update(init).added == 2);
    CHECK(f->landmarks()[1].id == 1);
    // Re-observed where they are: matched, nothing new.
    const std::vector<Observation> again{{-1, 10.05, 0.51}, {-1, 9.97, -0.49}};
    const auto r = f->update(again);
    CHECK(r.corrected == 2);
    CHECK(r.added == 0);
    CHECK(f->landmarkCount() == 2);
    // Far from both: new.
    CHECK(f->update(std::vector<Observation>{{-1, 20.0, 0.0}}).added == 1);
    // Two landmarks 0.1 m apart, then a sighting between them: ambiguous, dropped.
    LandmarkSlamOptions o2 = o;
    std::unique_ptr<LandmarkFilter> g;
    if (rb)
      g = std::make_unique<RbUkfSlam>(o2);
    else
      g = std::make_unique<EkfSlam>(o2);
    const double d = 0.05 / 10.0;  // bearing offsets of +-5 cm at 10 m
    CHECK(g->update(std::vector<Observation>{{-1, 10.0, d}, {-1, 10.0, -d}}).added == 2);
    const auto amb = g->update(std::vector<Observation>{{-1, 10.0, 0.0}});
    CHECK(amb.corrected == 0);
    CHECK(g->rejections().ambiguous == 1);
    // Known-id mode is not used here: an id-less sighting is fine.
    CHECK(g->rejections().unknown_id == 0);
  }
}
