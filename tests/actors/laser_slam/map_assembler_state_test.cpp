// map_assembler and the saved SLAM state (through the mock-mailbox harness): it writes what it
// holds at stop, and a second assembler loading that state publishes the same map.
#include <tessera/laser_slam/map_assembler_actor.hpp>
#include <tessera/laser_slam/slam_state.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <filesystem>
#include <numbers>
#include <string>

#include "../../shared_data.hpp"

using namespace tessera;
using Catch::Contains;
using laser_slam::MapAssemblerActor;
using laser_slam::MapAssemblerOptions;

namespace {

namespace fs = std::filesystem;

/// A 30 x 20 submap at 0.1 m: free inside, a wall along its top row, unknown on its right edge,
/// an id-dependent obstacle so that the submaps differ.
void pushSubmap(ActorHarness& h, int id, const Pose2& carried) {
  h.push<msg::Submap>("submaps", [&](auto& b) {
    setHeader(b.initHeader(), 1000 + id, "map", 0);
    b.setId(static_cast<std::uint32_t>(id));
    auto g = b.initGrid();
    g.setResolution(0.1f);
    g.setWidth(30);
    g.setHeight(20);
    writePose(g.initOrigin(), Pose2{-1.0, -0.5, 0.0});
    auto cells = mutableViewInt8(g.initCells(600));
    for (int r = 0; r < 20; ++r)
      for (int c = 0; c < 30; ++c)
        cells[static_cast<std::size_t>(r * 30 + c)] = r == 19   ? std::int8_t{100}
                                                      : c == 29 ? std::int8_t{-1}
                                                                : std::int8_t{3};
    cells[static_cast<std::size_t>(5 * 30 + 3 + 4 * id)] = 97;
    writePose(b.initGlobalPose(), carried);
    b.setFinished(id != 2);
  });
}

void pushConstraint(ActorHarness& h, int from, int to, const Pose2& relative, bool revisit,
                    const Eigen::Matrix3d* covariance) {
  h.push<msg::SubmapConstraint>("constraints", [&](auto& b) {
    setHeader(b.initHeader(), 1000, "map", 0);
    b.setFromId(static_cast<std::uint32_t>(from));
    b.setToId(static_cast<std::uint32_t>(to));
    writePose(b.initRelative(), relative, covariance);
    b.setKind(revisit ? msg::SubmapConstraint::Kind::REVISIT
                      : msg::SubmapConstraint::Kind::HAND_OVER);
  });
}

/// A camera calibration as camera_network_slam publishes it; `scale` varies the homography.
void pushCalibration(ActorHarness& h, int camera, int submap, double scale, double rms_px) {
  h.push<msg::CameraCalibration>("camera_calibrations", [&](auto& b) {
    setHeader(b.initHeader(), 1500 + camera, "submap_" + std::to_string(submap), 0);
    b.setCameraId(camera);
    b.setSubmapId(static_cast<std::uint32_t>(submap));
    const double h9[9] = {100.0 * scale, 1.0 / 3.0, 320.5, -2.0, 101.0 * scale,
                          240.25,        1e-3,      2e-3,  1.0};
    auto list = b.initHomography(9);
    for (unsigned k = 0; k < 9; ++k) list.set(k, h9[k]);
    b.setRmsPx(rms_px);
    b.setCoverage(0.2);
    b.setCondition(1234.5);
    b.setPairs(120);
    b.setInliers(117);
  });
}

grid::OccupancyMap mapOf(const Message<msg::OccupancyGrid>& m) {
  grid::OccupancyMap out;
  out.resolution = m->getResolution();
  out.width = static_cast<int>(m->getWidth());
  out.height = static_cast<int>(m->getHeight());
  out.origin = toPose2(m->getOrigin());
  const auto cells = viewInt8(m->getCells());
  out.cells.assign(cells.begin(), cells.end());
  return out;
}

}  // namespace

TEST_CASE(
    "map assembler saves its SLAM state at stop and a loading assembler publishes the same "
    "map",
    "[map_assembler][slam_state]") {
  const fs::path out = test::scratchDir("assembler_state");
  MapAssemblerOptions o;
  o.optimized_poses = true;
  ActorHarness h(std::make_unique<MapAssemblerActor>(o), out.string());
  Eigen::Matrix3d cov = Eigen::Vector3d(0.01, 0.02, 0.001).asDiagonal();
  cov(0, 1) = cov(1, 0) = 0.003;
  pushSubmap(h, 0, Pose2{});
  pushConstraint(h, 0, 1, Pose2(2.5, 0.2, 0.1), false, &cov);
  pushSubmap(h, 1, Pose2(9.0, 9.0, 0.0));
  pushConstraint(h, 1, 2, Pose2(2.0, 1.0, std::numbers::pi / 2), false, &cov);
  pushSubmap(h, 2, Pose2(9.0, 9.0, 0.0));
  pushConstraint(h, 2, 0, Pose2(-1.0, 4.0, -1.4), true, &cov);
  pushConstraint(h, 2, 0, Pose2(-1.0, 4.0, -1.4), true, &cov);    // re-sent: kept once
  pushConstraint(h, 1, 0, Pose2(-2.0, 0.0, 0.0), true, nullptr);  // no covariance: not saved
  // The optimiser moves submaps 1 and 2; those poses are the ones saved.
  h.push<msg::SubmapPoses>("submap_poses", [&](auto& b) {
    setHeader(b.initHeader(), 2000, "map", 0);
    auto poses = b.initPoses(3);
    const Pose2 optimised[] = {Pose2{}, Pose2(2.4, 0.25, 0.12), Pose2(4.1, 1.3, 1.6)};
    for (unsigned k = 0; k < 3; ++k) {
      poses[k].setId(k);
      writePose(poses[k].initPose(), optimised[k]);
    }
  });
  h.runUntilIdle();
  h.stop();
  const auto maps = h.published<msg::OccupancyGrid>("map");
  REQUIRE_FALSE(maps.empty());
  const grid::OccupancyMap first = mapOf(maps.back());
  REQUIRE(first.width > 30);

  const fs::path state_dir = out / "slam_state";
  REQUIRE(fs::exists(state_dir / "state.yaml"));
  const laser_slam::SlamState state = laser_slam::loadSlamState(state_dir);
  CHECK(state.frame_id == "map");
  REQUIRE(state.submaps.size() == 3);
  CHECK(state.submaps[1].origin.x == 2.4);
  CHECK(state.submaps[1].origin.y == 0.25);
  CHECK(state.submaps[2].origin.theta == 1.6);
  CHECK(state.submaps[0].finished);
  CHECK_FALSE(state.submaps[2].finished);
  CHECK(state.submaps[1].grid.width == 30);
  CHECK(state.submaps[1].grid.origin.x == -1.0);
  CHECK(state.submaps[1].grid.at(7, 5) == 97);
  CHECK(state.submaps[1].grid.at(29, 0) == -1);
  REQUIRE(state.constraints.size() == 3);
  CHECK(state.constraints[0].from == 0);
  CHECK(state.constraints[0].to == 1);
  CHECK_FALSE(state.constraints[0].revisit);
  CHECK(state.constraints[2].revisit);
  CHECK(state.constraints[2].relative.y == 4.0);
  CHECK((state.constraints[0].information * cov - Eigen::Matrix3d::Identity()).norm() < 1e-9);

  MapAssemblerOptions lo;
  lo.load_state = state_dir.string();
  lo.state_dir.clear();
  ActorHarness loaded(std::make_unique<MapAssemblerActor>(lo), (out / "second").string());
  loaded.advance(0);  // starts the actor: the map goes out in start()
  const auto served = loaded.published<msg::OccupancyGrid>("map");
  REQUIRE(served.size() == 1);
  const grid::OccupancyMap second = mapOf(served.front());
  CHECK(second.width == first.width);
  CHECK(second.height == first.height);
  CHECK(second.resolution == first.resolution);
  CHECK(second.origin.x == first.origin.x);
  CHECK(second.origin.y == first.origin.y);
  CHECK(second.cells == first.cells);
  CHECK(std::string(served.front()->getHeader().getFrameId().cStr()) == "map");
  loaded.stop();  // and again at stop, for writers that keep the latest
  CHECK(loaded.published<msg::OccupancyGrid>("map").size() == 2);
  CHECK_FALSE(fs::exists(out / "second" / "slam_state"));  // state_dir empty: none written
  // It serves the saved map only: nothing to subscribe to.
  CHECK_THROWS_WITH(loaded.push<msg::Submap>("submaps", [](auto&) {}),
                    Contains("does not subscribe"));
}

TEST_CASE(
    "map assembler saves each camera's latest calibration with the map, and a loaded state "
    "keeps them",
    "[map_assembler][slam_state]") {
  const fs::path out = test::scratchDir("assembler_cameras");
  const MapAssemblerOptions o;
  ActorHarness h(std::make_unique<MapAssemblerActor>(o), out.string());
  pushSubmap(h, 0, Pose2{});
  pushSubmap(h, 1, Pose2(3.0, 0.0, 0.0));
  pushCalibration(h, 4, 0, 1.0, 0.9);
  pushCalibration(h, 1, 1, 1.0, 1.1);
  pushCalibration(h, 4, 1, 1.5, 0.7);   // camera 4 calibrated again, in submap 1: replaces
  pushCalibration(h, 6, 9, 1.0, 0.8);   // submap 9 never arrives: not saved
  pushCalibration(h, 7, 0, 1.0, -1.0);  // invalid (negative RMS): rejected
  h.push<msg::CameraCalibration>("camera_calibrations", [&](auto& b) {
    b.setCameraId(8);
    b.initHomography(8);  // too few values: rejected
  });
  h.runUntilIdle();
  h.stop();
  Summary summary;
  h.actor().summarize(summary);
  CHECK(std::get<std::int64_t>(summary["camera_calibrations_received"]) == 6);
  CHECK(std::get<std::int64_t>(summary["camera_calibrations_rejected"]) == 2);
  CHECK(std::get<std::int64_t>(summary["state_cameras"]) == 2);
  CHECK(std::get<std::int64_t>(summary["state_cameras_unsaved"]) == 1);

  const fs::path state_dir = out / "slam_state";
  const laser_slam::SlamState state = laser_slam::loadSlamState(state_dir);
  REQUIRE(state.cameras.size() == 2);
  CHECK(state.cameras[0].camera == 1);
  CHECK(state.cameras[0].submap == 1);
  CHECK(state.cameras[0].rms_px == 1.1);
  CHECK(state.cameras[1].camera == 4);
  CHECK(state.cameras[1].submap == 1);
  CHECK(state.cameras[1].stamp_ns == 1504);
  CHECK(state.cameras[1].rms_px == 0.7);
  CHECK(state.cameras[1].floor_to_pixel(0, 0) == 150.0);
  CHECK(state.cameras[1].floor_to_pixel(0, 1) == 1.0 / 3.0);
  CHECK(state.cameras[1].floor_to_pixel(2, 1) == 2e-3);
  CHECK(state.cameras[1].coverage == 0.2);
  CHECK(state.cameras[1].condition == 1234.5);
  CHECK(state.cameras[1].pairs == 120);
  CHECK(state.cameras[1].inliers == 117);

  // Loaded and saved again, the cameras are still there, unchanged.
  MapAssemblerOptions lo;
  lo.load_state = state_dir.string();
  ActorHarness loaded(std::make_unique<MapAssemblerActor>(lo), (out / "second").string());
  loaded.advance(0);
  loaded.stop();
  const laser_slam::SlamState again = laser_slam::loadSlamState(out / "second" / "slam_state");
  REQUIRE(again.cameras.size() == 2);
  CHECK(again.cameras[1].floor_to_pixel == state.cameras[1].floor_to_pixel);
  CHECK(again.cameras[0].stamp_ns == state.cameras[0].stamp_ns);
}

TEST_CASE("map assembler without an output folder or state_dir writes no state",
          "[map_assembler][slam_state]") {
  const fs::path out = test::scratchDir("assembler_no_state");
  MapAssemblerOptions o;
  o.state_dir.clear();
  ActorHarness h(std::make_unique<MapAssemblerActor>(o), out.string());
  pushSubmap(h, 0, Pose2{});
  h.runUntilIdle();
  h.stop();
  CHECK(h.publishedCount("map") == 1);
  CHECK(fs::is_empty(out));
}

TEST_CASE("map assembler load_state errors name the path and the field", "[map_assembler]") {
  const fs::path root = test::scratchDir("assembler_bad_state");
  MapAssemblerOptions o;
  o.load_state = (root / "absent").string();
  CHECK_THROWS_AS(MapAssemblerActor(o), ConfigError);
  CHECK_THROWS_WITH(MapAssemblerActor(o),
                    Contains("load_state") && Contains("absent") && Contains("no such directory"));
  // A valid state whose frame is not the map's frame.
  laser_slam::SlamState state;
  state.frame_id = "world";
  laser_slam::SavedSubmap s;
  s.grid.width = s.grid.height = 2;
  s.grid.cells = {0, 100, -1, 0};
  state.submaps.push_back(s);
  laser_slam::saveSlamState(state, root / "world");
  o.load_state = (root / "world").string();
  CHECK_THROWS_WITH(MapAssemblerActor(o), Contains("frame 'world'") && Contains("'map'"));
  // And one with no submaps: nothing to serve.
  state.submaps.clear();
  laser_slam::saveSlamState(state, root / "none");
  o.load_state = (root / "none").string();
  o.frame_id = "world";
  CHECK_THROWS_WITH(MapAssemblerActor(o), Contains("holds no submaps"));
}
