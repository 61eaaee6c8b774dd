// MapMerger: two robots' submaps of one synthetic floor, each in the robot's own frame, joined
// at the true relative frame; a look-alike floor (the same rooms turned half a turn, one cabinet
// moved) is never joined; bad input is refused by name.
#include <tessera/laser_slam/map_merger.hpp>

#include <catch2/catch.hpp>

#include "synthetic_floor.hpp"

#include <cmath>
#include <numbers>
#include <vector>

using tessera::Pose2;
using tessera::grid::OccupancyMap;
using tessera::laser_slam::MapMerger;
using tessera::laser_slam::MapMergerOptions;
using tessera::laser_slam::SubmapTrajectoryPose;
using tessera::test::drive;
using tessera::test::floorBoxes;
using tessera::test::submap;

TEST_CASE("MapMerger joins two robots at their true relative frame", "[laser_slam][map_merger]") {
  const Pose2 frame_a(1.5, 2.0, 0.3), frame_b(17.0, 13.0, 2.5);  // starts on the floor
  MapMerger merger(2);
  const auto boxes = floorBoxes();
  REQUIRE(merger
              .addSubmap(0, 0, submap(frame_a, {5, 6}, 9, boxes), Pose2(),
                         drive(frame_a, {3, 3}, {6, 9}))
              .empty());
  CHECK_FALSE(merger.frame(1));
  REQUIRE(merger
              .addSubmap(1, 0, submap(frame_b, {6, 7}, 8, boxes), Pose2(),
                         drive(frame_b, {7, 10}, {4, 4}))
              .empty());
  const auto frame = merger.frame(1);
  REQUIRE(frame);
  const Pose2 truth = frame_a.inverse() * frame_b;
  INFO("estimate " << frame->x << " " << frame->y << " " << frame->theta << ", truth " << truth.x
                   << " " << truth.y << " " << truth.theta);
  CHECK(std::hypot(frame->x - truth.x, frame->y - truth.y) < 0.1);
  CHECK(std::abs(tessera::angleDiff(frame->theta, truth.theta)) < 0.02);
  CHECK(merger.closures().size() >= 2);
  CHECK(merger.counts().joins == 1);
  for (const auto& c : merger.closures()) CHECK(c.global);
  CHECK(merger.relativeFrame(1, 0));
  // The merged map holds both robots' cells: wider than either submap alone.
  const OccupancyMap merged = merger.assemble();
  CHECK(merged.width * merged.resolution > 26.0);

  SECTION("a later submap is searched near where the frames put it") {
    const Pose2 second(2.0, -1.0, 0.4);  // robot b's second submap origin, in its own frame
    const Pose2 second_in_floor = frame_b * second;
    REQUIRE(merger
                .addSubmap(1, 1, submap(second_in_floor, {12, 8}, 8, boxes), second,
                           drive(second_in_floor, {10, 9}, {15, 8}))
                .empty());
    CHECK(merger.counts().joined_searches > 0);
    CHECK(merger.closures().size() > 2);
    const auto after = merger.frame(1);
    REQUIRE(after);
    CHECK(std::hypot(after->x - truth.x, after->y - truth.y) < 0.1);
  }

  SECTION("a robot's optimiser moving its submaps moves its frame with them") {
    merger.setPose(1, 0, Pose2(0.5, 0.0, 0.0));
    const auto moved = merger.frame(1);
    REQUIRE(moved);
    const Pose2 expected = truth * Pose2(0.5, 0.0, 0.0).inverse();
    CHECK(std::hypot(moved->x - expected.x, moved->y - expected.y) < 0.1);
  }
}

TEST_CASE("MapMerger places a robot joined only through another one", "[laser_slam][map_merger]") {
  // a and c saw opposite corners of the floor and share nothing; b drove through both.
  const Pose2 frame_a(1.5, 2.0, 0.3), frame_b(10.0, 8.0, -1.2), frame_c(18.0, 14.0, 2.8);
  MapMerger merger(3);
  const auto boxes = floorBoxes();
  merger.addSubmap(0, 0, submap(frame_a, {5, 6}, 8, boxes), Pose2(),
                   drive(frame_a, {3, 3}, {6, 9}));
  merger.addSubmap(1, 0, submap(frame_b, {10, 8}, 14, boxes), Pose2(),
                   drive(frame_b, {3, 4}, {16, 12}));
  CHECK(merger.frame(1));
  CHECK_FALSE(merger.frame(2));
  merger.addSubmap(2, 0, submap(frame_c, {17, 13}, 5, boxes), Pose2(),
                   drive(frame_c, {18.5, 9.5}, {15, 14.5}));
  for (int robot : {1, 2}) {
    INFO("robot " << robot);
    const auto frame = merger.frame(robot);
    REQUIRE(frame);
    const Pose2 truth = frame_a.inverse() * (robot == 1 ? frame_b : frame_c);
    CHECK(std::hypot(frame->x - truth.x, frame->y - truth.y) < 0.15);
    CHECK(std::abs(tessera::angleDiff(frame->theta, truth.theta)) < 0.03);
  }
  CHECK(merger.relativeFrame(2, 0));       // either way round
  for (const auto& c : merger.closures())  // c was placed through b alone
    CHECK_FALSE(((c.robot_a == 0 && c.robot_b == 2) || (c.robot_a == 2 && c.robot_b == 0)));
}

TEST_CASE("MapMerger never joins a look-alike floor", "[laser_slam][map_merger]") {
  // Robot b is on another floor: the same rooms turned half a turn, one cabinet elsewhere. The
  // global search finds the turned alignment; overlaying the submaps shows the cabinet on free
  // floor, so nothing is joined.
  const Pose2 frame_a(1.5, 2.0, 0.3), frame_b(17.0, 13.0, 2.5);
  MapMerger merger(2);
  REQUIRE(merger
              .addSubmap(0, 0, submap(frame_a, {5, 6}, 9, floorBoxes()), Pose2(),
                         drive(frame_a, {3, 3}, {6, 9}))
              .empty());
  REQUIRE(merger
              .addSubmap(1, 0, submap(frame_b, {14, 9}, 8, floorBoxes(true), true), Pose2(),
                         drive(frame_b, {13, 6}, {16, 12}))
              .empty());
  CHECK_FALSE(merger.frame(1));
  CHECK(merger.closures().empty());
  CHECK(merger.counts().global_searches > 0);
  CHECK(merger.counts().conflicting >= 1);  // found, and refused by the overlay
}

TEST_CASE("MapMerger needs matches of min_agreeing patches before it joins",
          "[laser_slam][map_merger]") {
  const Pose2 frame_a(1.5, 2.0, 0.3), frame_b(17.0, 13.0, 2.5);
  MapMergerOptions options;
  options.min_agreeing = 20;  // more patches than the submap has
  MapMerger merger(2, options);
  const auto boxes = floorBoxes();
  merger.addSubmap(0, 0, submap(frame_a, {5, 6}, 9, boxes), Pose2(),
                   drive(frame_a, {3, 3}, {6, 9}));
  merger.addSubmap(1, 0, submap(frame_b, {6, 7}, 8, boxes), Pose2(),
                   drive(frame_b, {7, 10}, {4, 4}));
  CHECK(merger.counts().candidates >= 2);
  CHECK_FALSE(merger.frame(1));
  CHECK(merger.closures().empty());
}

TEST_CASE("MapMerger refuses bad input by name", "[laser_slam][map_merger]") {
  MapMerger merger(2);
  const auto boxes = floorBoxes();
  const Pose2 frame(1.5, 2.0, 0.3);
  const auto grid = submap(frame, {5, 6}, 9, boxes);
  const auto path = drive(frame, {3, 3}, {6, 9});
  CHECK(merger.addSubmap(2, 0, grid, Pose2(), path).find("robot 2") != std::string::npos);
  CHECK(merger.addSubmap(-1, 0, grid, Pose2(), path).find("robot -1") != std::string::npos);
  CHECK(merger.addSubmap(0, 0, grid, Pose2(std::nan(""), 0, 0), path).find("non-finite") !=
        std::string::npos);
  CHECK_FALSE(merger.addSubmap(0, 1, OccupancyMap{}, Pose2(), path).empty());
  OccupancyMap truncated = grid;
  truncated.cells.resize(truncated.cells.size() / 2);
  CHECK_FALSE(merger.addSubmap(0, 2, truncated, Pose2(), path).empty());
  CHECK(merger.counts().submaps_rejected == 5);
  // No trajectory, or one of NaN poses: kept (it can still be matched against), no patches.
  std::vector<SubmapTrajectoryPose> nan_path = {{0, Pose2(std::nan(""), 0, 0)}};
  CHECK(merger.addSubmap(0, 3, grid, Pose2(), nan_path).empty());
  CHECK(merger.addSubmap(0, 4, grid, Pose2(), {}).empty());
  CHECK(merger.counts().patches == 0);
  CHECK(merger.submapPose(0, 3));
  // A repeated id keeps the first copy.
  CHECK(merger.addSubmap(0, 3, grid, Pose2(5, 5, 0), path).empty());
  CHECK(merger.submapPose(0, 3)->x == 0.0);
  merger.setPose(0, 3, Pose2(std::nan(""), 0, 0));  // ignored
  CHECK(merger.submapPose(0, 3)->x == 0.0);

  CHECK_THROWS_WITH(MapMerger(1), Catch::Contains("at least 2 robots"));
  MapMergerOptions bad;
  bad.patch_radius = 50;
  CHECK_THROWS_WITH(MapMerger(2, bad), Catch::Contains("patch_radius"));
  bad = {};
  bad.max_conflict_fraction = std::nan("");
  CHECK_THROWS_WITH(MapMerger(2, bad), Catch::Contains("max_conflict_fraction"));
  bad = {};
  bad.min_agreeing = 0;
  CHECK_THROWS_WITH(MapMerger(2, bad), Catch::Contains("min_agreeing"));
}
