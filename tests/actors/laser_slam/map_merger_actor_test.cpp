// map_merger actor: two robots' submaps from their namespaced topics joined into one map, each
// robot's pose sent back in it, the frames file written; bad options named; truncated, empty and
// NaN input counted and left out, never a crash.
#include <tessera/laser_slam/map_merger_actor.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "../../shared_data.hpp"
#include "synthetic_floor.hpp"

using namespace tessera;
using laser_slam::MapMergerActor;
using laser_slam::MapMergerActorOptions;

namespace {

MapMergerActorOptions twoRobots() {
  MapMergerActorOptions o;
  o.robots = {"r1", "r2"};
  return o;
}

/// A finished submap message: `grid` (cells as given, possibly inconsistent), origin `origin`
/// in the robot's chained frame, its trajectory.
void pushSubmap(ActorHarness& h, const std::string& robot, int id, const grid::OccupancyMap& grid,
                const Pose2& origin, const std::vector<laser_slam::SubmapTrajectoryPose>& path,
                std::size_t cells = static_cast<std::size_t>(-1)) {
  h.push<msg::Submap>(robot + "/submaps", [&](msg::Submap::Builder b) {
    setHeader(b.initHeader(), 1000 + id, "map", 0);
    b.setId(static_cast<std::uint32_t>(id));
    auto g = b.initGrid();
    g.setResolution(static_cast<float>(grid.resolution));
    g.setWidth(static_cast<std::uint32_t>(grid.width));
    g.setHeight(static_cast<std::uint32_t>(grid.height));
    writePose(g.initOrigin(), grid.origin);
    const std::size_t n = std::min(cells, grid.cells.size());
    auto out = g.initCells(static_cast<unsigned>(n));
    for (std::size_t k = 0; k < n; ++k) out[static_cast<unsigned>(k)] = grid.cells[k];
    writePose(b.initGlobalPose(), origin);
    b.setFinished(true);
    auto t = b.initTrajectory(static_cast<unsigned>(path.size()));
    for (std::size_t k = 0; k < path.size(); ++k) {
      auto p = t[static_cast<unsigned>(k)];
      p.setStampNs(path[k].stamp_ns);
      p.setX(path[k].pose.x);
      p.setY(path[k].pose.y);
      p.setTheta(path[k].pose.theta);
    }
  });
}

void pushPose(ActorHarness& h, const std::string& topic, Nanos stamp, const Pose2& p) {
  h.push<msg::PoseStamped>(topic, [&](msg::PoseStamped::Builder b) {
    setHeader(b.initHeader(), stamp, "map", 0);
    writePose(b.initPose(), p);
  });
}

}  // namespace

TEST_CASE("map_merger joins two robots' submaps and sends each its pose in the merged map",
          "[laser_slam][map_merger]") {
  const auto dir = test::scratchDir("map_merger_actor");
  ActorHarness h(std::make_unique<MapMergerActor>(twoRobots()), dir.string());
  const Pose2 frame_a(1.5, 2.0, 0.3), frame_b(17.0, 13.0, 2.5);
  const auto boxes = test::floorBoxes();
  pushSubmap(h, "r1", 0, test::submap(frame_a, {5, 6}, 9, boxes), Pose2(),
             test::drive(frame_a, {3, 3}, {6, 9}));
  pushPose(h, "r2/pose", 10, Pose2(1, 0, 0));  // not joined yet: nothing to send back
  h.runUntilIdle();
  CHECK(h.publishedCount("r2/map_pose") == 0);
  pushSubmap(h, "r2", 0, test::submap(frame_b, {6, 7}, 8, boxes), Pose2(),
             test::drive(frame_b, {7, 10}, {4, 4}));
  h.runUntilIdle();
  pushPose(h, "r2/pose", 20, Pose2(1, 0, 0));
  pushPose(h, "r2/trajectory_final", 20, Pose2(1, 0, 0));
  h.runUntilIdle();
  const auto sent = h.published<msg::PoseStamped>("r2/map_pose");
  REQUIRE(sent.size() == 1);
  // r2's pose (1, 0) in its own frame, in r1's: where frame_a⁻¹ ⊕ frame_b puts it.
  const Pose2 truth = frame_a.inverse() * frame_b * Pose2(1, 0, 0);
  const Pose2 got = toPose2(sent[0]->getPose());
  CHECK(std::hypot(got.x - truth.x, got.y - truth.y) < 0.1);
  h.stop();
  CHECK(h.publishedCount("map") == 1);
  CHECK(h.publishedCount("r2/trajectory_merged") == 1);
  std::ifstream in(dir / "robot_frames.json");
  std::stringstream text;
  text << in.rdbuf();
  CHECK_THAT(text.str(), Catch::Contains("\"name\": \"r2\", \"joined\": true"));
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("robots_joined")) == 2);
  CHECK(std::get<std::int64_t>(s.at("inter_robot_closures")) >= 2);
}

TEST_CASE("map_merger counts truncated, empty and NaN input and leaves it out",
          "[laser_slam][map_merger]") {
  // No output folder that exists: the frames file fails by name, the run still stops.
  ActorHarness h(std::make_unique<MapMergerActor>(twoRobots()), "/nonexistent/tessera_out");
  const Pose2 frame(1.5, 2.0, 0.3);
  const auto grid = test::submap(frame, {5, 6}, 9, test::floorBoxes());
  const auto path = test::drive(frame, {3, 3}, {6, 9});
  pushSubmap(h, "r1", 0, grid, Pose2(), path, grid.cells.size() / 2);  // truncated cells
  grid::OccupancyMap empty;
  empty.resolution = 0.05;
  pushSubmap(h, "r1", 1, empty, Pose2(), path);                   // no cells
  pushSubmap(h, "r1", 2, grid, Pose2(std::nan(""), 0, 0), path);  // NaN origin
  h.push<msg::SubmapPoses>("r1/submap_poses", [](msg::SubmapPoses::Builder b) {
    auto poses = b.initPoses(1);
    poses[0].setId(0);
    writePose(poses[0].initPose(), Pose2(std::nan(""), 0, 0));
  });
  pushPose(h, "r1/pose", 5, Pose2(std::nan(""), 1, 0));
  h.runUntilIdle();
  h.stop();
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("merger_submaps_rejected")) == 3);
  CHECK(std::get<std::int64_t>(s.at("merger_submaps")) == 0);
  CHECK(std::get<std::int64_t>(s.at("poses_invalid")) == 2);
  CHECK(std::get<std::int64_t>(s.at("robots_joined")) == 1);  // r1 itself
  CHECK_THAT(std::get<std::string>(s.at("frames_write_error")),
             Catch::Contains("robot_frames.json"));
}

TEST_CASE("map_merger refuses bad options by name", "[laser_slam][map_merger]") {
  MapMergerActorOptions o;
  o.robots = {"r1"};
  CHECK_THROWS_WITH(MapMergerActor(o), Catch::Contains("robots") && Catch::Contains("two"));
  o.robots = {"r1", "r1"};
  CHECK_THROWS_WITH(MapMergerActor(o), Catch::Contains("'r1' is named twice"));
  o.robots = {"r1", "/r2"};
  CHECK_THROWS_WITH(MapMergerActor(o), Catch::Contains("'/r2'"));
  o.robots = {"r1", "fleet//r2"};  // the profile's namespace rule: no empty part
  CHECK_THROWS_WITH(MapMergerActor(o), Catch::Contains("'fleet//r2'"));
  o = twoRobots();
  o.publish_period_s = std::nan("");
  CHECK_THROWS_WITH(MapMergerActor(o), Catch::Contains("publish_period_s"));
  o = twoRobots();
  o.merger.coarse_factor = 0;
  CHECK_THROWS_WITH(MapMergerActor(o), Catch::Contains("coarse_factor"));
}
