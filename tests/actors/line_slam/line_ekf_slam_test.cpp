// Tests for the LineEkfSlam core: observation model, motion models, association, tentative
// lines, duplicate merging, rejected input, and a closed loop in the simulated room.
#include <tessera/line_slam/line_ekf_slam.hpp>
#include <tessera/line_slam/line_extraction.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include "../laser_slam/sim_scans.hpp"

using namespace tessera;
using line_slam::Association;
using line_slam::LineEkfSlam;
using line_slam::LineEkfSlamOptions;
using tessera::Pose2;
using tessera::line_slam::LineSegment;

namespace {

/// A segment from a to b in the robot frame with a small (r, φ) covariance.
LineSegment segment(const Eigen::Vector2d& a, const Eigen::Vector2d& b, double sigma = 0.003) {
  LineSegment s;
  const Eigen::Vector2d d = (b - a).normalized();
  s.line.phi = std::atan2(d.x(), -d.y());
  s.line.r = a.dot(Eigen::Vector2d(std::cos(s.line.phi), std::sin(s.line.phi)));
  tessera::line_slam::normalizeLine(s.line.r, s.line.phi);
  s.line.covariance = Eigen::Matrix2d::Identity() * sigma * sigma;
  s.line.valid = true;
  s.p0 = a;
  s.p1 = b;
  return s;
}

LineEkfSlamOptions immediate() {
  LineEkfSlamOptions o;
  o.tentative_sightings = 1;
  o.merge_interval = 0;
  return o;
}

}  // namespace

TEST_CASE("observation model predicts a wall seen from the robot with its Jacobian",
          "[lines][line_ekf_slam]") {
  LineEkfSlam slam(immediate());
  slam.reset(Pose2(1.0, 0.5, 0.3));
  // The wall x = 4 seen from (1, 0.5, 0.3).
  const Pose2 p = slam.pose();
  const LineSegment world = segment({4, -1}, {4, 2});
  slam.update({tessera::line_slam::transformSegment(world, p.inverse())});
  REQUIRE(slam.lineCount() == 1);
  const auto line = slam.lines()[0];
  CHECK(line.r == Approx(4.0).margin(1e-9));
  CHECK(line.phi == Approx(0.0).margin(1e-9));
  Eigen::Matrix<double, 2, 5> h;
  const Eigen::Vector2d z = slam.predict(0, &h);
  CHECK(z(0) == Approx(3.0).margin(1e-9));
  CHECK(z(1) == Approx(-0.3).margin(1e-9));
  // Numerical Jacobian over (x, y, θ, r, φ).
  const auto f = [](const Eigen::Matrix<double, 5, 1>& v) {
    double r = v(3) - (v(0) * std::cos(v(4)) + v(1) * std::sin(v(4)));
    double phi = v(4) - v(2);
    tessera::line_slam::normalizeLine(r, phi);
    return Eigen::Vector2d(r, phi);
  };
  Eigen::Matrix<double, 5, 1> v;
  v << 1.0, 0.5, 0.3, 4.0, 0.0;
  for (int k = 0; k < 5; ++k) {
    Eigen::Matrix<double, 5, 1> dv = Eigen::Matrix<double, 5, 1>::Zero();
    dv(k) = 1e-6;
    const Eigen::Vector2d num = (f(v + dv) - f(v - dv)) / 2e-6;
    CHECK(h(0, k) == Approx(num(0)).margin(1e-6));
    CHECK(h(1, k) == Approx(num(1)).margin(1e-6));
  }
}

TEST_CASE("new line covariance follows the augmentation Gx P Gx^T + Gz R Gz^T",
          "[lines][line_ekf_slam]") {
  LineEkfSlam slam(immediate());
  Eigen::Matrix3d p0 = Eigen::Matrix3d::Zero();
  p0.diagonal() << 0.04, 0.09, 0.01;
  slam.reset(Pose2(0, 0, 0), p0);
  // A wall y = 2 ahead-left: φ = π/2, observed r = 2.
  const LineSegment s = segment({-1, 2}, {1, 2});
  slam.update({s});
  REQUIRE(slam.lineCount() == 1);
  const auto& c = slam.covariance();
  // At the origin: Gx = [[0, 1, 0], [0, 0, 1]], Gz = I.
  const Eigen::Matrix2d r =
      s.line.covariance +
      Eigen::Vector2d(slam.options().obs_sigma_r * slam.options().obs_sigma_r,
                      slam.options().obs_sigma_phi * slam.options().obs_sigma_phi)
          .asDiagonal()
          .toDenseMatrix();
  CHECK(c(3, 3) == Approx(0.09 + r(0, 0)));
  CHECK(c(4, 4) == Approx(0.01 + r(1, 1)));
  CHECK(c(3, 1) == Approx(0.09));  // the line moves with the robot's y
  CHECK(c(4, 2) == Approx(0.01));  // and its angle with the robot's heading
}

TEST_CASE("differential-drive and car-like predictions move the pose and grow its covariance",
          "[lines][line_ekf_slam]") {
  LineEkfSlam slam;
  slam.reset(Pose2(0, 0, 0));
  REQUIRE(slam.predictOdometry(Pose2(1.0, 0.0, std::numbers::pi / 2)));
  CHECK(slam.pose().x == Approx(1.0));
  CHECK(slam.pose().theta == Approx(std::numbers::pi / 2));
  CHECK(slam.poseCovariance()(0, 0) > 0);
  CHECK(slam.poseCovariance()(2, 2) > 0);
  // Car-like: a quarter circle of radius L / sin(γ).
  slam.reset(Pose2(0, 0, 0));
  const double v = 1.0, gamma = 0.2, l = 1.0, dt = 0.001;
  const double radius = l / std::sin(gamma);
  const int steps = static_cast<int>(std::round(std::numbers::pi / 2 * radius / (v * dt)));
  for (int k = 0; k < steps; ++k) REQUIRE(slam.predictCarLike(v, gamma, l, dt));
  CHECK(slam.pose().theta == Approx(std::numbers::pi / 2).margin(2e-3));
  CHECK(slam.poseCovariance()(1, 1) > 0);
  // Bad motion is counted and changes nothing.
  const Pose2 before = slam.pose();
  CHECK_FALSE(slam.predictCarLike(v, gamma, 0.0, dt));
  CHECK_FALSE(slam.predictOdometry(Pose2(std::numeric_limits<double>::quiet_NaN(), 0, 0)));
  CHECK(slam.stats().motion_rejected == 2);
  CHECK(slam.pose().x == before.x);
}

TEST_CASE("association picks the right line among near-parallel candidates",
          "[lines][line_ekf_slam]") {
  for (const Association mode : {Association::kCost, Association::kThreshold}) {
    LineEkfSlamOptions o = immediate();
    o.association = mode;
    o.gate_distance = 0.055;  // narrow enough to map both walls, wide enough to see both
    LineEkfSlam slam(o);
    slam.reset(Pose2(0, 0, 0));
    // Two parallel walls 6 cm apart (a door frame and its wall, a shelf front).
    slam.update({segment({-1, 1.00}, {2, 1.00}), segment({-1, 1.06}, {2, 1.06})});
    REQUIRE(slam.lineCount() == 2);
    // A segment 1 cm from the second one and 5 cm from the first: both pass the gates.
    bool ambiguous = false;
    const int k = slam.associate(segment({0, 1.05}, {1.5, 1.05}), &ambiguous);
    CHECK(ambiguous);
    if (mode == Association::kCost)
      CHECK(k == 1);  // lowest weighted cost
    else
      CHECK(k == 0);  // the old method takes the first line within the gates
  }
}

TEST_CASE("a new line stays tentative until its third consecutive sighting",
          "[lines][line_ekf_slam]") {
  LineEkfSlamOptions o;
  o.merge_interval = 0;
  LineEkfSlam slam(o);
  slam.reset(Pose2(0, 0, 0));
  const LineSegment wall = segment({3, -1}, {3, 1});
  slam.update({wall});
  CHECK(slam.lineCount() == 0);
  CHECK(slam.tentativeCount() == 1);
  slam.update({wall});
  CHECK(slam.lineCount() == 0);
  slam.update({wall});
  CHECK(slam.lineCount() == 1);
  CHECK(slam.tentativeCount() == 0);
  CHECK(slam.stats().tentative_created == 1);
  CHECK(slam.stats().tentative_promoted == 1);
  // Seen, missed, seen: the sightings are not consecutive, nothing enters the map.
  const LineSegment other = segment({-1, 2}, {1, 2});
  slam.update({wall, other});
  slam.update({wall});
  slam.update({wall, other});
  slam.update({wall, other});
  CHECK(slam.lineCount() == 1);
  CHECK(slam.stats().tentative_dropped == 1);
  slam.update({wall, other});
  CHECK(slam.lineCount() == 2);
}

TEST_CASE("duplicate map lines are merged once their extents meet", "[lines][line_ekf_slam]") {
  LineEkfSlamOptions o = immediate();
  o.merge_interval = 1;
  LineEkfSlam slam(o);
  Eigen::Matrix3d p0 = Eigen::Matrix3d::Identity() * 1e-4;
  slam.reset(Pose2(0, 0, 0), p0);
  // Two pieces of the wall y = 2, 2 m apart: no overlap, so two lines.
  slam.update({segment({-3, 2}, {-2, 2})});
  slam.update({segment({1, 2.01}, {2, 2.01})});
  REQUIRE(slam.lineCount() == 2);
  CHECK(slam.stats().lines_merged == 0);
  // A long sighting joins them: it updates one, whose extent now reaches the other.
  slam.update({segment({-2.5, 2}, {1.5, 2})});
  CHECK(slam.lineCount() == 1);
  CHECK(slam.stats().lines_merged == 1);
  const auto line = slam.lines()[0];
  CHECK(line.r == Approx(2.0).margin(0.02));
  CHECK(std::min(line.p0().x(), line.p1().x()) == Approx(-3.0).margin(0.05));
  CHECK(std::max(line.p0().x(), line.p1().x()) == Approx(2.0).margin(0.05));
  CHECK(slam.state().size() == 5);
  CHECK(slam.covariance().rows() == 5);
}

TEST_CASE("non-finite and too short segments are rejected with a count", "[lines][line_ekf_slam]") {
  LineEkfSlam slam(immediate());
  LineSegment nan = segment({3, -1}, {3, 1});
  nan.line.r = std::numeric_limits<double>::quiet_NaN();
  LineSegment bad_cov = segment({3, -1}, {3, 1});
  bad_cov.line.covariance(0, 0) = std::numeric_limits<double>::infinity();
  slam.update({nan, bad_cov, segment({3, 0}, {3, 0.1}), {}});
  CHECK(slam.stats().segments == 4);
  CHECK(slam.stats().segments_rejected == 4);
  CHECK(slam.lineCount() == 0);
  CHECK(slam.state().allFinite());
}

TEST_CASE("line EKF SLAM keeps the pose in the simulated room while odometry drifts",
          "[lines][line_ekf_slam]") {
  const auto sim = test::simulateRoomLoop();
  const tessera::line_slam::LineExtractor extractor;
  LineEkfSlam slam;
  slam.reset(sim.scans[0].odometry);
  double max_error = 0;
  for (std::size_t k = 0; k < sim.scans.size(); ++k) {
    const auto& s = sim.scans[k];
    if (k > 0) slam.predictOdometry(tessera::between(sim.scans[k - 1].odometry, s.odometry));
    slam.update(extractor.extract(sim.range(s)));
    max_error = std::max(max_error, (slam.pose().translation() - s.truth.translation()).norm());
  }
  const auto& last = sim.scans.back();
  const double slam_error = (slam.pose().translation() - last.truth.translation()).norm();
  const double odom_error = (last.odometry.translation() - last.truth.translation()).norm();
  INFO("final error " << slam_error << " m (max " << max_error << "), odometry " << odom_error
                      << " m, lines " << slam.lineCount());
  CHECK(odom_error > 0.5);
  CHECK(slam_error < 0.07);
  CHECK(max_error < 0.15);
  CHECK(std::abs(tessera::angleDiff(slam.pose().theta, last.truth.theta)) <
        0.5 * std::numbers::pi / 180);
  CHECK(slam.lineCount() > 10);
  CHECK(slam.lineCount() < 45);
}
