// camera_network_slam through the mock-mailbox harness: calibration at a first visit (held for
// the submap's smoothed trajectory), a revisit constraint from a later submap, bad input; the
// published calibration saved with the map by the map assembler, and the calibrations file.
#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/sensor.capnp.h>
#include <tessera/msg/submap.capnp.h>
#include <tessera/camera_network/camera_calibration_file.hpp>
#include <tessera/camera_network/camera_network_slam_actor.hpp>
#include <tessera/laser_slam/map_assembler_actor.hpp>
#include <tessera/laser_slam/slam_state.hpp>
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/sim/camera_network.hpp>

#include <catch2/catch.hpp>

#include "../../shared_data.hpp"
#include "../laser_slam/submap_messages.hpp"

#include <cmath>
#include <filesystem>
#include <random>
#include <vector>

namespace camera_network_slam_actor_test {

using namespace tessera;
using tessera::camera_network::CameraNetworkSlamActor;
using tessera::camera_network::CameraNetworkSlamOptions;

struct Drive {
  Drive(ActorHarness& harness, sim::EnvironmentCamera cam) : h(harness), camera(std::move(cam)) {}
  ActorHarness& h;
  sim::EnvironmentCamera camera;
  std::mt19937_64 rng{4};
  std::int64_t t = 0;
  std::uint32_t seq = 0;
  Pose2 origin;  // current submap's origin in the chained frame (= world here)
  std::vector<std::pair<std::int64_t, Pose2>> trajectory;  // current submap's, its own frame
  bool odometry = false;  // also publish odometry (in a frame of its own) at each frame

  /// One frame at 10 Hz: the chained pose, and the camera's detection when in view.
  void frame(const Pose2& truth, bool nan_pixel = false) {
    t += 100'000'000;
    ++seq;
    h.push<msg::PoseStamped>("chained_pose", [&](msg::PoseStamped::Builder b) {
      setHeader(b.initHeader(), t, "map", seq);
      writePose(b.initPose(), truth);
    });
    if (odometry)
      h.push<msg::Odometry>("odom", [&](msg::Odometry::Builder b) {
        setHeader(b.initHeader(), t, "odom", seq);
        writePose(b.initPose(), Pose2(5.0, -3.0, 0.4) * truth);
      });
    trajectory.emplace_back(t, origin.inverse() * truth);
    if (camera.inView(truth.translation())) {
      std::normal_distribution<double> n(0.0, 1.0);
      const Eigen::Vector2d px = *camera.project(truth.translation());
      h.push<msg::MarkerDetection>("camera_detections", [&](msg::MarkerDetection::Builder b) {
        setHeader(b.initHeader(), t, "camera_0", seq);
        b.setCameraId(camera.id());
        b.setDetected(true);
        b.setU(nan_pixel ? std::nan("") : px.x() + n(rng));
        b.setV(px.y() + n(rng));
        b.setPixelStd(1.0);
      });
    }
    h.runUntilIdle();
  }
  void event(bool entered) {
    h.push<msg::CameraEvent>("camera_events", [&](msg::CameraEvent::Builder b) {
      setHeader(b.initHeader(), t, "camera_0", seq);
      b.setCameraId(camera.id());
      b.setEntered(entered);
    });
    h.runUntilIdle();
  }
  /// A visit of the camera driving a loop of 1 m radius under it (a calibration's motion).
  void calibrationLoop() {
    const Eigen::Vector2d c = camera.site().position;
    event(true);
    for (double a = 0; a < 2 * M_PI; a += 0.03)
      frame(Pose2(c + Eigen::Vector2d(std::cos(a), std::sin(a)), a + M_PI / 2));
    event(false);
  }
  /// The builder finishes the current submap (with its smoothed trajectory) and starts `id` at
  /// the robot's pose `start` (`lost`: the builder was lost, as after a kidnapping), with a
  /// position std of `std_m` [m].
  void handOver(std::uint32_t from, std::uint32_t id, const Pose2& start, bool lost = false,
                double std_m = 0.05) {
    h.push<msg::Submap>("submaps", [&](msg::Submap::Builder b) {
      test::fillSubmap(b, static_cast<int>(from), origin, t);
      auto list = b.initTrajectory(static_cast<unsigned>(trajectory.size()));
      for (unsigned k = 0; k < trajectory.size(); ++k) {
        list[k].setStampNs(trajectory[k].first);
        list[k].setX(trajectory[k].second.x);
        list[k].setY(trajectory[k].second.y);
        list[k].setTheta(trajectory[k].second.theta);
      }
    });
    h.push<msg::SubmapConstraint>("constraints", [&](msg::SubmapConstraint::Builder b) {
      setHeader(b.initHeader(), t, "map", seq);
      b.setFromId(from);
      b.setToId(id);
      const Eigen::Matrix3d cov = Eigen::Vector3d(std_m * std_m, std_m * std_m, 0.01).asDiagonal();
      writePose(b.initRelative(), origin.inverse() * start, &cov);
      b.setKind(msg::SubmapConstraint::Kind::HAND_OVER);
      b.setLost(lost);
    });
    h.runUntilIdle();
    origin = start;
    trajectory.clear();
  }
};

sim::EnvironmentCamera camera() {
  sim::CameraSite s;
  s.id = 0;
  s.position = {4.0, 0.0};
  s.yaw = 0.3;
  s.pitch = 0.06;
  return {s, sim::CameraIntrinsics{}};
}

TEST_CASE("camera_network_slam calibrates at a first visit and sends a revisit constraint later",
          "[camera_network][actor]") {
  CameraNetworkSlamOptions o;
  ActorHarness h(std::make_unique<CameraNetworkSlamActor>(o));
  Drive d(h, camera());
  d.odometry = true;
  const Eigen::Vector2d c = d.camera.site().position;
  // Submap 0: a loop of 1 m radius under the camera.
  d.event(true);
  for (double a = 0; a < 2 * M_PI; a += 0.03)
    d.frame(Pose2(c + Eigen::Vector2d(std::cos(a), std::sin(a)), a + M_PI / 2));
  d.frame(Pose2(c + Eigen::Vector2d(1.0, 0.0), M_PI / 2), /*nan_pixel=*/true);
  d.event(false);
  auto summary = [&] {
    Summary s;
    h.actor().summarize(s);
    return s;
  };
  // Held until submap 0 finishes.
  CHECK(std::get<std::int64_t>(summary()["calibrations"]) == 0);
  const Pose2 start1(12, 5, 2.0);
  d.handOver(0, 1, start1);
  CHECK(std::get<std::int64_t>(summary()["calibrations"]) == 1);
  CHECK(std::get<double>(summary()["calibration_rms_px"]) < 1.5);
  CHECK(std::get<std::int64_t>(summary()["sightings_ignored"]) == 1);  // the NaN pixel

  // Submap 1: a straight pass through the view.
  d.event(true);
  for (double s = -3; s <= 3; s += 0.03) d.frame(Pose2(c + Eigen::Vector2d(s, 0.3), 0.0));
  d.event(false);
  CHECK(h.published<msg::SubmapConstraint>("camera_constraints").empty());
  d.handOver(1, 2, Pose2(20, 0, 0));
  const auto out = h.published<msg::SubmapConstraint>("camera_constraints");
  REQUIRE(out.size() == 1);
  CHECK(out[0]->getKind() == msg::SubmapConstraint::Kind::REVISIT);
  CHECK(out[0]->getFromId() == 1);
  CHECK(out[0]->getToId() == 0);
  const Pose2 rel = toPose2(out[0]->getRelative());
  const Pose2 truth = start1.inverse();  // submap 0's origin (the world origin) in submap 1
  CHECK(std::hypot(rel.x - truth.x, rel.y - truth.y) < 0.05);
  CHECK(std::abs(angleDiff(rel.theta, truth.theta)) < 0.02);
  Eigen::Matrix3d cov;
  REQUIRE(readCovariance(out[0]->getRelative(), cov));
  CHECK(cov.allFinite());
  CHECK(cov.determinant() > 0);
  CHECK(std::get<std::int64_t>(summary()["revisits"]) == 1);
  // Both visits' paths were the odometry's (the SLAM is exact here, so nothing else changes).
  CHECK(std::get<std::int64_t>(summary()["sightings_with_odometry"]) ==
        std::get<std::int64_t>(summary()["sightings"]));
  CHECK(std::get<std::int64_t>(summary()["visits_odometry_shaped"]) == 2);
}

TEST_CASE("camera_network_slam relocalises after a lost hand-over and refines it later",
          "[camera_network][actor]") {
  CameraNetworkSlamOptions o;
  ActorHarness h(std::make_unique<CameraNetworkSlamActor>(o));
  Drive d(h, camera());
  const Eigen::Vector2d c = d.camera.site().position;
  auto summary = [&] {
    Summary s;
    h.actor().summarize(s);
    return s;
  };
  d.calibrationLoop();
  d.handOver(0, 1, Pose2(12, 5, 2.0), /*lost=*/false, /*std_m=*/100.0);
  REQUIRE(std::get<std::int64_t>(summary()["calibrations"]) == 1);
  // A hand-over with a wide covariance is not a lost one: only the flag says so.
  CHECK(std::get<std::int64_t>(summary()["unanchored_handovers"]) == 0);

  // Lost in submap 1: submap 2 starts where the builder's odometry guessed; here the chain and
  // the world agree, so the revisit is checked against the truth as usual.
  const Pose2 start2(-3, 2, -1.0);
  d.handOver(1, 2, start2, /*lost=*/true);
  CHECK(std::get<std::int64_t>(summary()["unanchored_handovers"]) == 1);
  d.event(true);
  for (double s = -3; s <= 3; s += 0.03) d.frame(Pose2(c + Eigen::Vector2d(s, 0.3), 0.0));
  d.event(false);
  // At the visit's end, without waiting for submap 2 to finish.
  auto out = h.published<msg::SubmapConstraint>("camera_constraints");
  REQUIRE(out.size() == 1);
  CHECK(out[0]->getFromId() == 2);
  CHECK(out[0]->getToId() == 0);
  CHECK(std::get<std::int64_t>(summary()["relocalisations"]) == 1);
  Eigen::Matrix3d provisional, refined;
  REQUIRE(readCovariance(out[0]->getRelative(), provisional));
  // Submap 2 finishes: the same visit on its smoothed trajectory, weighing far more.
  d.handOver(2, 3, Pose2(20, 0, 0));
  out = h.published<msg::SubmapConstraint>("camera_constraints");
  REQUIRE(out.size() == 2);
  CHECK(out[1]->getFromId() == 2);
  CHECK(out[1]->getToId() == 0);
  REQUIRE(readCovariance(out[1]->getRelative(), refined));
  CHECK(provisional.trace() > 20 * refined.trace());
  const Pose2 rel = toPose2(out[1]->getRelative());
  const Pose2 truth = start2.inverse();
  CHECK(std::hypot(rel.x - truth.x, rel.y - truth.y) < 0.05);
  CHECK(std::get<std::int64_t>(summary()["relocalisations_refined"]) == 1);
  CHECK(std::get<std::int64_t>(summary()["revisits"]) == 2);
}

TEST_CASE(
    "camera_network_slam publishes each calibration, writes the calibrations file, and the map "
    "assembler saves it with the map",
    "[camera_network][actor][slam_state]") {
  namespace fs = std::filesystem;
  const fs::path out = test::scratchDir("camera_network_slam_calibrations");
  fs::create_directories(out / "cameras");
  fs::create_directories(out / "map");
  const CameraNetworkSlamOptions o;
  ActorHarness h(std::make_unique<CameraNetworkSlamActor>(o), (out / "cameras").string());
  Drive d(h, camera());
  d.calibrationLoop();
  CHECK(h.published<msg::CameraCalibration>("camera_calibrations").empty());  // held
  d.handOver(0, 1, Pose2(12, 5, 2.0));
  const auto published = h.published<msg::CameraCalibration>("camera_calibrations");
  REQUIRE(published.size() == 1);
  const auto& actor = static_cast<const CameraNetworkSlamActor&>(h.actor());
  REQUIRE(actor.builder().calibrations().count(0));
  const auto& cal = actor.builder().calibrations().at(0);
  const auto& m = published[0];
  CHECK(m->getCameraId() == 0);
  CHECK(m->getSubmapId() == 0);
  CHECK(m->getHeader().getStampNs() == cal.stamp_ns);
  CHECK(std::string(m->getHeader().getFrameId().cStr()) == "submap_0");
  REQUIRE(m->getHomography().size() == 9);
  for (unsigned k = 0; k < 9; ++k) CHECK(m->getHomography()[k] == cal.homography.h(k / 3, k % 3));
  CHECK(m->getRmsPx() == cal.homography.quality.rms_px);
  CHECK(m->getCoverage() == cal.homography.quality.coverage);
  CHECK(m->getCondition() == cal.homography.quality.condition);
  CHECK(m->getPairs() == static_cast<std::uint32_t>(cal.homography.quality.pairs));
  CHECK(m->getInliers() == static_cast<std::uint32_t>(cal.homography.quality.inliers));
  CHECK(m->getInliers() > 30);

  // At stop the calibrations file holds the same calibration, exactly.
  h.stop();
  CHECK(h.published<msg::CameraCalibration>("camera_calibrations").size() == 1);  // no new one
  const auto records =
      camera_network::readCameraCalibrations(out / "cameras" / "camera_calibrations.yaml");
  REQUIRE(records.size() == 1);
  CHECK(records[0] == camera_network::calibrationRecord(cal));

  // The map assembler keeps the published calibration and saves it with submap 0.
  const laser_slam::MapAssemblerOptions ao;
  ActorHarness assembler(std::make_unique<laser_slam::MapAssemblerActor>(ao),
                         (out / "map").string());
  assembler.push<msg::Submap>(
      "submaps", [&](msg::Submap::Builder b) { test::fillSubmap(b, 0, Pose2(), 1000); });
  assembler.push<msg::CameraCalibration>("camera_calibrations", m);
  assembler.runUntilIdle();
  assembler.stop();
  const laser_slam::SlamState state = laser_slam::loadSlamState(out / "map" / "slam_state");
  REQUIRE(state.cameras.size() == 1);
  const laser_slam::SavedCamera& saved = state.cameras[0];
  CHECK(saved.camera == 0);
  CHECK(saved.submap == 0);
  CHECK(saved.stamp_ns == cal.stamp_ns);
  CHECK(saved.floor_to_pixel == cal.homography.h);
  CHECK(saved.rms_px == cal.homography.quality.rms_px);
  CHECK(saved.coverage == cal.homography.quality.coverage);
  CHECK(saved.condition == cal.homography.quality.condition);
  CHECK(saved.pairs == cal.homography.quality.pairs);
  CHECK(saved.inliers == cal.homography.quality.inliers);
}

TEST_CASE("camera_network_slam ignores bad input and counts it", "[camera_network][actor]") {
  const CameraNetworkSlamOptions o;
  ActorHarness h(std::make_unique<CameraNetworkSlamActor>(o));
  Drive d(h, camera());
  // A hand-over from a submap nobody started, with a NaN pose: ignored.
  h.push<msg::SubmapConstraint>("constraints", [&](msg::SubmapConstraint::Builder b) {
    setHeader(b.initHeader(), 0, "map", 0);
    b.setFromId(9);
    b.setToId(10);
    writePose(b.initRelative(), Pose2(std::nan(""), 0, 0));
    b.setKind(msg::SubmapConstraint::Kind::HAND_OVER);
  });
  // Odometry that is not finite.
  h.push<msg::Odometry>("odom", [&](msg::Odometry::Builder b) {
    setHeader(b.initHeader(), 0, "odom", 0);
    writePose(b.initPose(), Pose2(0, std::nan(""), 0));
  });
  // A missed detection.
  h.push<msg::MarkerDetection>("camera_detections", [&](msg::MarkerDetection::Builder b) {
    setHeader(b.initHeader(), 0, "camera_0", 0);
    b.setCameraId(0);
    b.setDetected(false);
  });
  h.runUntilIdle();
  // A short visit: refused calibration at the end of the run, never a crash.
  d.event(true);
  for (int k = 0; k < 10; ++k) d.frame(Pose2(4.0 + 0.03 * k, 0.0, 0.0));
  d.event(false);
  h.stop();
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s["misses"]) == 1);
  CHECK(std::get<std::int64_t>(s["odometry_ignored"]) == 1);
  CHECK(std::get<std::int64_t>(s["calibrations"]) == 0);
  CHECK(std::get<std::int64_t>(s["calibrations_refused"]) == 1);
  CHECK(std::get<std::string>(s["last_refusal"]).find("too few pairs") != std::string::npos);
  CHECK(h.published<msg::SubmapConstraint>("camera_constraints").empty());
}

TEST_CASE("camera_network_slam options are checked", "[camera_network][actor]") {
  CameraNetworkSlamOptions gap;
  gap.max_pose_gap_s = -1;
  CHECK_THROWS_AS(CameraNetworkSlamActor(gap), ConfigError);
  CameraNetworkSlamOptions pairs;
  pairs.builder.calibration.min_pairs = 2;
  CHECK_THROWS_WITH(CameraNetworkSlamActor(pairs), Catch::Contains("min_pairs"));
}

}  // namespace camera_network_slam_actor_test
