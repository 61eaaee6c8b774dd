// Revisit constraints from a calibrated camera: the transform fit (camera_localization.hpp)
// against a hand computation, and CameraConstraintBuilder's visits (calibrate, revisit, stale).
#include <tessera/camera_network/camera_constraint_builder.hpp>
#include <tessera/camera_network/camera_localization.hpp>
#include <tessera/sim/camera_network.hpp>

#include <Eigen/LU>
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace camera_constraint_builder_test {

using tessera::Pose2;
using namespace tessera::camera_network;

TEST_CASE("the revisit transform between two maps matches a hand computation",
          "[camera_network][revisit]") {
  // Robot at (2, 1, 0.5) in map i and at (1, -1, -0.3) in map j. Map j's origin in map i:
  // θ = 0.5 - (-0.3) = 0.8; t = (2, 1) - R(0.8) (1, -1)
  //   = (2 - (cos 0.8 + sin 0.8), 1 - (sin 0.8 - cos 0.8))
  //   = (2 - (0.6967067 + 0.7173561), 1 - (0.7173561 - 0.6967067)) = (0.5859372, 0.9793506).
  const Pose2 t = mapTransformFromPoses({2, 1, 0.5}, {1, -1, -0.3});
  CHECK(t.x == Approx(0.5859372).margin(1e-6));
  CHECK(t.y == Approx(0.9793506).margin(1e-6));
  CHECK(t.theta == Approx(0.8).margin(1e-12));
  // And it does what it says: the robot's pose in j, moved by t, is its pose in i.
  const Pose2 back = t * Pose2(1, -1, -0.3);
  CHECK(back.x == Approx(2).margin(1e-12));
  CHECK(back.y == Approx(1).margin(1e-12));
  CHECK(back.theta == Approx(0.5).margin(1e-12));
}

TEST_CASE("the transform fit recovers a known transform and refuses what cannot give one",
          "[camera_network][revisit]") {
  const Pose2 truth(3.0, -2.0, 1.1);
  std::mt19937_64 rng(2);
  std::normal_distribution<double> n(0.0, 0.01);
  std::vector<PointCorrespondence> pts;
  for (double a = 0; a < 3.0; a += 0.05) {
    const Eigen::Vector2d child(std::cos(a) * 1.2, std::sin(a) * 0.8 + 0.3 * a);
    PointCorrespondence p;
    p.child = child + Eigen::Vector2d(n(rng), n(rng));
    p.child_covariance = 1e-4 * Eigen::Matrix2d::Identity();
    p.parent = truth * child;
    p.parent_covariance = Eigen::Matrix2d::Zero();
    pts.push_back(p);
  }
  MapTransformOptions options;
  options.min_point_std_m = 1e-4;
  const auto r = fitMapTransform(pts, options);
  INFO(r.refusal);
  REQUIRE(r.fit);
  const Eigen::Vector3d e(r.fit->transform.x - truth.x, r.fit->transform.y - truth.y,
                          tessera::angleDiff(r.fit->transform.theta, truth.theta));
  CHECK(e.dot(r.fit->covariance.inverse() * e) < 16.3);  // chi-square(3) 99.9 %
  CHECK(r.fit->rms_m < 0.02);

  // A robot standing still: no heading.
  std::vector<PointCorrespondence> still(30, pts.front());
  auto bad = fitMapTransform(still, options);
  CHECK_FALSE(bad.fit);
  CHECK(bad.refusal.find("need 0.50 m of motion") != std::string::npos);
  // Too few, and NaN ones do not count.
  std::vector<PointCorrespondence> few(pts.begin(), pts.begin() + 5);
  few.push_back(pts[6]);
  few.back().child.x() = std::numeric_limits<double>::quiet_NaN();
  bad = fitMapTransform(few, options);
  CHECK(bad.refusal == "too few sightings: 5 (need 10)");
  // Positions that disagree (the camera moved): refused with the RMS.
  auto moved = pts;
  for (std::size_t k = 0; k < moved.size(); k += 2) moved[k].child.x() += 0.6;
  bad = fitMapTransform(moved, options);
  CHECK_FALSE(bad.fit);
  CHECK(bad.refusal.find("disagree") != std::string::npos);
}

/// Visits handled at their end with the poses given (no smoothed trajectories).
CameraConstraintBuilderOptions onlineOptions() {
  CameraConstraintBuilderOptions o;
  o.smoothed_poses = false;
  return o;
}

/// A robot that drives under one camera: its true poses, and what the SLAM reports in its
/// chained frame (exact within a submap, the submap placed wrongly by `placement_error`).
struct CameraWorld {
  tessera::sim::EnvironmentCamera camera{[] {
                                           tessera::sim::CameraSite s;
                                           s.id = 2;
                                           s.position = {5.0, 1.0};
                                           s.yaw = 0.4;
                                           s.roll = 0.05;
                                           return s;
                                         }(),
                                         tessera::sim::CameraIntrinsics{}};
  std::mt19937_64 rng{9};
  std::int64_t t = 0;

  /// A loop of radius r around the site starting at heading `start` [rad], then a straight
  /// exit; each pose (true) goes to `sighting` with the chained pose `chain * true`.
  template <class F>
  void drive(double r, double start, bool loop, const Pose2& chain, F&& sighting) {
    std::normal_distribution<double> n(0.0, 1.0);
    const double step = 0.03;
    auto emit = [&](const Pose2& truth) {
      t += 100'000'000;
      const auto px = camera.project(truth.translation());
      if (!px || !camera.inView(truth.translation())) return;
      CameraSighting s;
      s.stamp_ns = t;
      s.camera = camera.id();
      s.pixel = *px + Eigen::Vector2d(n(rng), n(rng));
      s.robot = chain * truth;
      sighting(s);
    };
    const Eigen::Vector2d c = camera.site().position;
    if (loop) {
      for (double a = 0; a < 2 * M_PI; a += step / r)
        emit(Pose2(c + r * Eigen::Vector2d(std::cos(start + a), std::sin(start + a)),
                   start + a + M_PI / 2));
    } else {
      // A straight pass through the view, heading `start`, passing r from the site.
      const Eigen::Vector2d dir(std::cos(start), std::sin(start));
      const Eigen::Vector2d side(-dir.y(), dir.x());
      for (double s = -4; s <= 4; s += step) emit(Pose2(c + r * side + s * dir, start));
    }
  }

  /// One visit: enter, drive as drive() does with every sighting given to `b`, leave.
  std::vector<CameraOutput> visit(CameraConstraintBuilder& b, double r, double start, bool loop,
                                  const Pose2& chain = Pose2()) {
    b.enter(camera.id(), t);
    drive(r, start, loop, chain, [&](const CameraSighting& s) { b.add(s); });
    return b.leave(camera.id(), t);
  }
};

TEST_CASE("a camera calibrated at its first visit gives the true revisit constraint later",
          "[camera_network][revisit]") {
  CameraWorld w;
  CameraConstraintBuilder b(onlineOptions());
  // First visit, in submap 0 (chained frame = world): a calibration loop.
  auto out = w.visit(b, 1.0, 0.0, true);
  REQUIRE(out.size() == 1);
  INFO(out[0].reason);
  REQUIRE(out[0].kind == CameraOutput::Kind::kCalibrated);
  CHECK(out[0].calibration->submap == 0);
  CHECK(out[0].calibration->homography.quality.rms_px < 1.5);

  // Much later, submap 7 starts at the true pose o7 but the chain placed it 0.8 m and 0.1 rad
  // off (drift); the SLAM is exact inside submap 7.
  const Pose2 o7_true(9.0, 4.0, 2.0);
  const Pose2 drift(0.5, -0.6, 0.1);
  const Pose2 o7_chained = drift * o7_true;
  REQUIRE(b.addSubmap(7, o7_chained));
  out = w.visit(b, 0.4, 2.5, false, drift);
  REQUIRE(out.size() == 1);
  INFO(out[0].reason);
  REQUIRE(out[0].kind == CameraOutput::Kind::kRevisit);
  CHECK(out[0].from == 7);
  CHECK(out[0].to == 0);
  // Submap 0's origin (the world origin) in submap 7's frame is o7_true⁻¹.
  const Pose2 truth = o7_true.inverse();
  const Eigen::Vector3d e(out[0].relative.x - truth.x, out[0].relative.y - truth.y,
                          tessera::angleDiff(out[0].relative.theta, truth.theta));
  CHECK(e.head<2>().norm() < 0.05);
  CHECK(std::abs(e(2)) < 0.02);
  CHECK(e.dot(out[0].covariance.inverse() * e) < 16.3);
  // The camera localisation: the robot's pose in submap 0 (the world) at the last sighting.
  CHECK(out[0].robot_in_to.isFinite());
}

TEST_CASE("a revisit's covariance holds the SLAM's one error of the whole visit (NEES)",
          "[camera_network][revisit]") {
  // The SLAM places the whole revisit in submap 7 with one rigid error (a shift and a turn about
  // the path's centre), shared by every sighting: the per-sighting slam_position_std_m averages
  // it away, slam_anchor_std_* does not. The calibration visit is exact here, so its anchor term
  // is left out to isolate the revisit's.
  auto meanNees = [](double anchor_m, double anchor_rad) {
    const double shift_std = 0.02, turn_std = 0.007;
    double sum = 0;
    int n = 0;
    for (int trial = 0; trial < 40; ++trial) {
      CameraWorld w;
      w.rng.seed(100 + trial);
      CameraConstraintBuilderOptions o = onlineOptions();
      o.calibration.anchor_std_m = 0;
      o.calibration.anchor_std_rad = 0;
      o.slam_anchor_std_m = anchor_m;
      o.slam_anchor_std_rad = anchor_rad;
      CameraConstraintBuilder b(o);
      auto out = w.visit(b, 1.0, 0.0, true);
      REQUIRE(out.size() == 1);
      REQUIRE(out[0].kind == CameraOutput::Kind::kCalibrated);
      const Pose2 o7_true(9.0, 4.0, 2.0);
      const Pose2 drift(0.5, -0.6, 0.1);
      const Pose2 o7_chained = drift * o7_true;
      REQUIRE(b.addSubmap(7, o7_chained));
      // The error in submap 7's frame: turn phi about the camera site (the path's centre), shift d.
      std::normal_distribution<double> g(0.0, 1.0);
      const Eigen::Vector2d c = o7_true.inverse() * w.camera.site().position;
      const double phi = turn_std * g(w.rng);
      const Eigen::Vector2d d(shift_std * g(w.rng), shift_std * g(w.rng));
      const Pose2 a = Pose2(c + d, 0.0) * Pose2(0, 0, phi) * Pose2(-c, 0.0);
      const Pose2 chain = o7_chained * a * o7_chained.inverse() * drift;
      out = w.visit(b, 0.4, 2.5, false, chain);
      REQUIRE(out.size() == 1);
      REQUIRE(out[0].kind == CameraOutput::Kind::kRevisit);
      const Pose2 truth = o7_true.inverse();
      const Eigen::Vector3d e(out[0].relative.x - truth.x, out[0].relative.y - truth.y,
                              tessera::angleDiff(out[0].relative.theta, truth.theta));
      sum += e.dot(out[0].covariance.inverse() * e);
      ++n;
    }
    return sum / n;
  };
  const double with = meanNees(0.02, 0.007), without = meanNees(0, 0);
  INFO("mean NEES with the SLAM's anchor " << with << ", without " << without);
  // chi-squared with 3 degrees of freedom: 3 on average; the fit and the calibration's pixel
  // noise add a little variance of their own, so a little under 3.
  CHECK(with > 1.5);
  CHECK(with < 4.5);
  CHECK(without > 3 * with);
}

TEST_CASE("a straight first pass is refused, the next visit's loop calibrates",
          "[camera_network][revisit]") {
  CameraWorld w;
  CameraConstraintBuilder b(onlineOptions());
  const int cam = w.camera.id();
  auto out = w.visit(b, 0.2, 0.3, false);
  REQUIRE(out.size() == 1);
  CHECK(out[0].kind == CameraOutput::Kind::kCalibrationRefused);
  CHECK(out[0].reason.find("on a line") != std::string::npos);
  CHECK(b.calibrations().empty());
  // NaN sightings are counted and ignored.
  CameraSighting nan;
  nan.camera = cam;
  nan.pixel = {std::nan(""), 1};
  CHECK_FALSE(b.add(nan));
  CHECK(b.ignoredSightings() == 1);
  out = w.visit(b, 1.2, 1.0, true);
  REQUIRE(out.size() == 1);
  CHECK(out[0].kind == CameraOutput::Kind::kCalibrated);
  CHECK(b.calibrations().count(cam) == 1);
}

TEST_CASE("a camera whose optics changed gives no constraint and is recalibrated after two visits",
          "[camera_network][revisit]") {
  CameraWorld w;
  CameraConstraintBuilder b(onlineOptions());
  const int cam = w.camera.id();
  REQUIRE(w.visit(b, 1.0, 0.0, true).at(0).kind == CameraOutput::Kind::kCalibrated);
  // Someone zoomed the camera in by 30 %: every later visit in another submap disagrees with
  // the SLAM. (Turning or shifting a camera that looks straight down moves its floor picture
  // almost rigidly, which one revisit cannot tell from a submap's drift: the graph's other
  // constraints have to.)
  const Eigen::Vector2d centre(320, 240);
  auto knocked = [&](CameraSighting s) {
    s.pixel = centre + 1.3 * (s.pixel - centre);
    b.add(s);
  };
  REQUIRE(b.addSubmap(1, Pose2(20, 0, 0)));
  b.enter(cam, w.t);
  w.drive(1.0, 0.5, true, Pose2(), knocked);
  auto out = b.leave(cam, w.t);
  REQUIRE(out.size() == 1);
  CHECK(out[0].kind == CameraOutput::Kind::kRevisitRefused);
  CHECK(b.calibrations().at(cam).submap == 0);
  REQUIRE(b.addSubmap(2, Pose2(-3, 2, 0.5)));
  b.enter(cam, w.t);
  w.drive(1.0, 1.5, true, Pose2(), knocked);
  out = b.leave(cam, w.t);
  REQUIRE(out.size() == 2);
  CHECK(out[0].kind == CameraOutput::Kind::kRevisitRefused);
  CHECK(out[1].kind == CameraOutput::Kind::kCalibrated);
  CHECK(b.calibrations().at(cam).submap == 2);
}

TEST_CASE("visits wait for the smoothed trajectory of their submap and calibrate from it",
          "[camera_network][revisit]") {
  // The online poses wobble by 5 cm (a particle filter between updates); the finished submap's
  // smoothed trajectory is exact. The calibration waits for it and fits to the pixel noise.
  CameraWorld w;
  CameraConstraintBuilder b(CameraConstraintBuilderOptions{});
  const int cam = w.camera.id();
  std::normal_distribution<double> wobble(0.0, 0.05);
  std::vector<std::pair<std::int64_t, Pose2>> smoothed;
  b.enter(cam, w.t);
  w.drive(1.0, 0.0, true, Pose2(), [&](CameraSighting s) {
    smoothed.emplace_back(s.stamp_ns, s.robot);
    s.robot = Pose2(s.robot.x + wobble(w.rng), s.robot.y + wobble(w.rng), s.robot.theta);
    b.add(s);
  });
  CHECK(b.leave(cam, w.t).empty());
  CHECK(b.heldVisits() == 1);
  // A trajectory that ends before the visit does not release it.
  CHECK(b.addTrajectory(0, {smoothed.begin(), smoothed.begin() + 10}).empty());
  CHECK(b.heldVisits() == 1);
  const auto out = b.addTrajectory(0, smoothed);
  REQUIRE(out.size() == 1);
  INFO(out[0].reason);
  REQUIRE(out[0].kind == CameraOutput::Kind::kCalibrated);
  CHECK(out[0].calibration->homography.quality.rms_px < 1.5);  // √2 px for 1 px per axis
  CHECK(b.heldVisits() == 0);

  // Without its trajectory a visit is released by finish(), with the online poses.
  CameraConstraintBuilder c(CameraConstraintBuilderOptions{});
  c.enter(cam, w.t);
  w.drive(1.0, 0.0, true, Pose2(), [&](const CameraSighting& s) { c.add(s); });
  CHECK(c.leave(cam, w.t).empty());
  const auto end = c.finish(w.t);
  REQUIRE(end.size() == 1);
  CHECK(end[0].kind == CameraOutput::Kind::kCalibrated);
}

TEST_CASE("after an unanchored submap the next calibrated camera relocalises at once",
          "[camera_network][revisit]") {
  // Smoothed poses on: visits normally wait for their submaps' trajectories.
  CameraWorld w;
  CameraConstraintBuilder b(CameraConstraintBuilderOptions{});
  CHECK(w.visit(b, 1.0, 0.0, true).empty());
  const auto cal = b.finish(w.t);  // calibrated in submap 0 from the online poses
  REQUIRE(cal.size() == 1);
  REQUIRE(cal[0].kind == CameraOutput::Kind::kCalibrated);

  // A kidnapping: the SLAM loses the map and starts submap 3, which its chain puts 30 m and
  // 2 rad from where it is; submap 4 follows it (anchored to 3, as at a camera entry).
  const Pose2 o4_true(6.0, -1.0, 0.7);
  const Pose2 wrong(30.0, -12.0, 2.0);
  REQUIRE(b.addSubmap(3, wrong * Pose2(4.0, 0.0, 0.0), /*anchored=*/false));
  CHECK(b.unanchoredSince() == 3u);
  REQUIRE(b.addSubmap(4, wrong * o4_true));
  auto out = w.visit(b, 0.4, 2.5, false, wrong);
  REQUIRE(out.size() == 1);  // at the visit's end, without waiting for smoothed trajectories
  INFO(out[0].reason);
  REQUIRE(out[0].kind == CameraOutput::Kind::kRevisit);
  CHECK(out[0].relocalisation);
  CHECK(out[0].from == 4);
  CHECK(out[0].to == 0);
  const Pose2 truth = o4_true.inverse();
  CHECK(std::hypot(out[0].relative.x - truth.x, out[0].relative.y - truth.y) < 0.05);
  CHECK(std::abs(tessera::angleDiff(out[0].relative.theta, truth.theta)) < 0.02);
  CHECK_FALSE(b.unanchoredSince());
  // Provisional: the same visit is held to be refit on smoothed poses.
  CHECK(b.heldVisits() == 1);
  // Anchored again: the next visit waits for the smoothed poses as usual.
  CHECK(w.visit(b, 0.4, 1.0, false, wrong).empty());
  CHECK(b.heldVisits() == 2);
  // No trajectory ever comes here, so finish() refits the relocalisation's visit on the same
  // (online) poses: the same constraint, with the covariance not scaled up.
  const auto later = b.finish(w.t);
  REQUIRE(later.size() == 2);
  REQUIRE(later[0].kind == CameraOutput::Kind::kRevisit);
  CHECK(later[0].refines_relocalisation);
  CHECK_FALSE(later[0].relocalisation);
  CHECK(later[0].from == 4);
  CHECK(later[0].to == 0);
  CHECK(later[0].relative.x == out[0].relative.x);
  CHECK(later[0].relative.theta == out[0].relative.theta);
  const double scale = CameraConstraintBuilderOptions{}.relocalisation_covariance_scale;
  CHECK(out[0].covariance.isApprox(scale * later[0].covariance, 1e-9));
  CHECK_FALSE(later[1].refines_relocalisation);
  CHECK(b.heldVisits() == 0);
}

TEST_CASE("a relocalisation is refined on the smoothed trajectory of its submap",
          "[camera_network][revisit]") {
  CameraWorld w;
  CameraConstraintBuilder b(CameraConstraintBuilderOptions{});
  CHECK(w.visit(b, 1.0, 0.0, true).empty());
  REQUIRE(b.finish(w.t).size() == 1);
  const Pose2 o4_true(6.0, -1.0, 0.7);
  const Pose2 wrong(30.0, -12.0, 2.0);
  REQUIRE(b.addSubmap(4, wrong * o4_true, /*anchored=*/false));
  // The online poses drift sideways at 1 cm/s; the smoothed trajectory is the truth.
  std::vector<std::pair<std::int64_t, Pose2>> smoothed;
  const std::int64_t t0 = w.t;
  b.enter(w.camera.id(), w.t);
  w.drive(0.4, 2.5, false, wrong, [&](CameraSighting s) {
    const double f = double(s.stamp_ns - t0) / 1e9;
    smoothed.emplace_back(s.stamp_ns, (wrong * o4_true).inverse() * s.robot);
    s.robot = s.robot * Pose2(0.0, 0.01 * f, 0.0);
    b.add(s);
  });
  const auto out = b.leave(w.camera.id(), w.t);
  REQUIRE(out.size() == 1);
  REQUIRE(out[0].kind == CameraOutput::Kind::kRevisit);
  CHECK(out[0].relocalisation);
  const auto later = b.addTrajectory(4, smoothed);
  REQUIRE(later.size() == 1);
  REQUIRE(later[0].kind == CameraOutput::Kind::kRevisit);
  CHECK(later[0].refines_relocalisation);
  const Pose2 truth = o4_true.inverse();
  const double err_online = std::hypot(out[0].relative.x - truth.x, out[0].relative.y - truth.y);
  const double err_smoothed =
      std::hypot(later[0].relative.x - truth.x, later[0].relative.y - truth.y);
  INFO("online " << err_online << " m, smoothed " << err_smoothed << " m");
  CHECK(err_smoothed < 0.02);
  CHECK(err_smoothed < 0.5 * err_online);
  // The provisional one weighs far less.
  CHECK(out[0].covariance.trace() > 20 * later[0].covariance.trace());
}

TEST_CASE("a visit's path is the odometry's, placed on the SLAM's wandering poses",
          "[camera_network][revisit]") {
  // The SLAM's poses wander by a few centimetres over the calibration loop (slowly, as scan
  // matching against a 5 cm grid does); the odometry, in its own frame, keeps the path's shape.
  const Pose2 odom_frame(-40.0, 7.0, 1.1);  // world -> odom frame, arbitrary
  const auto calibrate = [&](bool shape, bool with_odometry) {
    CameraWorld w;
    CameraConstraintBuilderOptions o = onlineOptions();
    o.odometry_shape = shape;
    CameraConstraintBuilder b(o);
    b.enter(w.camera.id(), w.t);
    w.drive(1.0, 0.0, true, Pose2(), [&](CameraSighting s) {
      const double t = 1e-9 * double(s.stamp_ns);
      if (with_odometry) s.odometry = odom_frame * s.robot;
      s.robot = s.robot * Pose2(0.03 * std::sin(1.3 * t), 0.03 * std::cos(1.1 * t), 0.0);
      b.add(s);
    });
    const auto out = b.leave(w.camera.id(), w.t);
    REQUIRE(out.size() == 1);
    REQUIRE(out[0].kind == CameraOutput::Kind::kCalibrated);
    return std::make_pair(out[0].calibration->homography.quality.rms_px, b.odometryShapedVisits());
  };
  const auto [slam_rms, slam_shaped] = calibrate(false, true);
  const auto [odom_rms, odom_shaped] = calibrate(true, true);
  const auto [none_rms, none_shaped] = calibrate(true, false);
  INFO("RMS with the SLAM's path " << slam_rms << " px, with the odometry's " << odom_rms
                                   << " px, without odometry " << none_rms << " px");
  CHECK(slam_shaped == 0);
  CHECK(odom_shaped == 1);
  CHECK(none_shaped == 0);
  CHECK(odom_rms < 1.6);  // √2 px for 1 px per axis: the pixel noise alone
  CHECK(slam_rms > odom_rms + 0.5);
  CHECK(none_rms == slam_rms);  // without odometry nothing changes
}

TEST_CASE("odometry that is not finite is ignored and long visits keep the SLAM's path",
          "[camera_network][revisit]") {
  CameraWorld w;
  CameraConstraintBuilderOptions o = onlineOptions();
  o.odometry_shape_max_s = 5.0;  // shorter than the loop
  CameraConstraintBuilder b(o);
  b.enter(w.camera.id(), w.t);
  int refused = 0;
  w.drive(1.0, 0.0, true, Pose2(), [&](CameraSighting s) {
    s.odometry = s.robot;
    if (!b.add(s)) ++refused;
    s.odometry = Pose2(std::nan(""), 0.0, 0.0);
    if (!b.add(s)) ++refused;
  });
  CHECK(refused > 50);
  CHECK(static_cast<std::uint64_t>(refused) == b.ignoredSightings());
  const auto out = b.leave(w.camera.id(), w.t);
  REQUIRE(out.size() == 1);
  CHECK(out[0].kind == CameraOutput::Kind::kCalibrated);
  CHECK(b.odometryShapedVisits() == 0);
}

TEST_CASE("the odometry path is placed where the SLAM's is", "[camera_network][revisit]") {
  // Exact SLAM and exact odometry in another frame: the calibration and the revisit after it are
  // the same as from the SLAM alone (without the visit path's refinement, which would fit the
  // pixels' noise into the path).
  const Pose2 odom_frame(3.0, -2.0, -0.6);
  const auto run = [&](bool shape) {
    CameraWorld w;
    CameraConstraintBuilderOptions o = onlineOptions();
    o.odometry_shape = shape;
    o.visit_path.enabled = false;
    CameraConstraintBuilder b(o);
    const auto withOdometry = [&](CameraSighting s) {
      s.odometry = odom_frame * s.robot;
      b.add(s);
    };
    b.enter(w.camera.id(), w.t);
    w.drive(1.0, 0.0, true, Pose2(), withOdometry);
    REQUIRE(b.leave(w.camera.id(), w.t).size() == 1);
    const Pose2 o7_true(9.0, 4.0, 2.0), drift(0.5, -0.6, 0.1);
    REQUIRE(b.addSubmap(7, drift * o7_true));
    b.enter(w.camera.id(), w.t);
    w.drive(0.4, 2.5, false, drift, withOdometry);
    const auto out = b.leave(w.camera.id(), w.t);
    REQUIRE(out.size() == 1);
    REQUIRE(out[0].kind == CameraOutput::Kind::kRevisit);
    return out[0].relative;
  };
  const Pose2 a = run(false), b = run(true);
  CHECK(std::hypot(a.x - b.x, a.y - b.y) < 1e-6);
  CHECK(std::abs(tessera::angleDiff(a.theta, b.theta)) < 1e-8);
}

TEST_CASE("only a calibration visit shaped by the odometry has its path refined",
          "[camera_network][revisit]") {
  const Pose2 odom_frame(3.0, -2.0, -0.6);
  const auto run = [&](bool shape, bool refine) {
    CameraWorld w;
    CameraConstraintBuilderOptions o = onlineOptions();
    o.odometry_shape = shape;
    o.visit_path.enabled = refine;
    CameraConstraintBuilder b(o);
    b.enter(w.camera.id(), w.t);
    w.drive(1.0, 0.0, true, Pose2(), [&](CameraSighting s) {
      s.odometry = odom_frame * s.robot;
      b.add(s);
    });
    const auto out = b.leave(w.camera.id(), w.t);
    REQUIRE(out.size() == 1);
    CHECK(out[0].kind == CameraOutput::Kind::kCalibrated);
    return b.refinedVisitPaths();
  };
  CHECK(run(true, true) == 1);
  CHECK(run(true, false) == 0);
  CHECK(run(false, true) == 0);
}

TEST_CASE("camera constraint builder options are checked", "[camera_network][revisit]") {
  CameraConstraintBuilderOptions o;
  o.marker = {0.1};
  CHECK_THROWS_WITH(CameraConstraintBuilder(o), Catch::Contains("marker"));
  o = {};
  o.calibration.min_pairs = 3;
  CHECK_THROWS_WITH(CameraConstraintBuilder(o), Catch::Contains("min_pairs"));
  o = {};
  o.revisit.max_rms_m = std::nan("");
  CHECK_THROWS_WITH(CameraConstraintBuilder(o), Catch::Contains("max_rms_m"));
  o = {};
  o.visit_path.distance_var_per_m = -1;
  CHECK_THROWS_WITH(CameraConstraintBuilder(o), Catch::Contains("distance_var_per_m"));
  o = {};
  o.relocalisation_covariance_scale = 0.5;
  CHECK_THROWS_WITH(CameraConstraintBuilder(o), Catch::Contains("relocalisation_covariance_scale"));
  o.relocalisation_covariance_scale = std::nan("");
  CHECK_THROWS_WITH(CameraConstraintBuilder(o), Catch::Contains("relocalisation_covariance_scale"));
  o = {};
  o.slam_anchor_std_m = -0.01;
  CHECK_THROWS_WITH(CameraConstraintBuilder(o), Catch::Contains("slam_anchor_std_m"));
  o = {};
  o.slam_anchor_std_rad = std::nan("");
  CHECK_THROWS_WITH(CameraConstraintBuilder(o), Catch::Contains("slam_anchor_std_rad"));
  o = {};
  o.odometry_shape_max_s = 0;
  CHECK_THROWS_WITH(CameraConstraintBuilder(o), Catch::Contains("odometry_shape_max_s"));
}

}  // namespace camera_constraint_builder_test
