#include <tessera/laser_slam/submap_graph.hpp>
#include <tessera/laser_slam/submap_trimmer.hpp>

#include <catch2/catch.hpp>

#include <numbers>

using tessera::Pose2;
using tessera::grid::OccupancyMap;
using tessera::laser_slam::SubmapConstraintInput;
using tessera::laser_slam::SubmapGraph;
using tessera::laser_slam::SubmapTrimmer;
using tessera::laser_slam::SubmapTrimmerOptions;

namespace submap_trimmer_test {

/// A w x h metre grid at 0.1 m, every cell known (free), its corner at the submap origin.
OccupancyMap knownGrid(double w, double h) {
  OccupancyMap g;
  g.resolution = 0.1;
  g.width = static_cast<int>(w / g.resolution);
  g.height = static_cast<int>(h / g.resolution);
  g.cells.assign(static_cast<std::size_t>(g.width) * g.height, 0);
  return g;
}

SubmapConstraintInput handOver(int from, int to, const Pose2& rel) {
  SubmapConstraintInput c;
  c.from = from;
  c.to = to;
  c.relative = rel;
  c.covariance = Eigen::Vector3d(0.01, 0.01, 0.001).asDiagonal();
  return c;
}

}  // namespace submap_trimmer_test
using namespace submap_trimmer_test;

TEST_CASE("a submap's footprint is the coarse cells its grid knows", "[lifelong]") {
  SubmapTrimmer t;  // 0.5 m cells
  OccupancyMap g = knownGrid(2.0, 1.0);
  CHECK(t.footprint(g).size() == 8);  // 4 x 2 coarse cells
  std::fill(g.cells.begin(), g.cells.end(), OccupancyMap::kUnknown);
  CHECK(t.footprint(g).empty());
  g.at(0, 0) = 100;  // one known cell is enough
  const auto one = t.footprint(g);
  REQUIRE(one.size() == 1);
  CHECK(one[0].x() == Approx(0.25));
  CHECK(one[0].y() == Approx(0.25));
  g.cells.pop_back();  // inconsistent size: no footprint rather than a read past the end
  CHECK(t.footprint(g).empty());
}

TEST_CASE("a submap newer ones cover is trimmed, the newest and the kept ones never",
          "[lifelong]") {
  SubmapTrimmerOptions o;
  o.keep_newest = 1;
  SubmapTrimmer t(o);
  const OccupancyMap room = knownGrid(6, 6);
  // Submaps 0 and 1 on the same room (lap 1 and lap 2); 2 in the next room, disjoint.
  for (int id = 0; id < 3; ++id) t.addSubmap(id, t.footprint(room));
  std::map<int, Pose2> poses = {
      {0, Pose2(0, 0, 0)}, {1, Pose2(0.1, -0.1, 0.01)}, {2, Pose2(20, 0, 0)}};
  // 0 is fully covered by 1 but kept (the anchor); 1 owns its room; 2 is the newest.
  CHECK(t.trim(poses, {0}).empty());
  // Without the protection, 0 goes; then nothing more.
  CHECK(t.trim(poses, {}) == std::vector<int>{0});
  CHECK(t.size() == 2);
  CHECK(t.trim(poses, {}).empty());
  // A fourth submap over room 1 covers 1, which now goes; 3 is the newest.
  t.addSubmap(3, t.footprint(room));
  poses[3] = Pose2(-0.1, 0.05, -0.02);
  CHECK(t.trim(poses, {}) == std::vector<int>{1});
  // A submap without a pose is never judged (nor does it cover anything).
  t.addSubmap(4, t.footprint(room));
  CHECK(t.trim(poses, {}).empty());
}

TEST_CASE("partly covered submaps stay until they own less than min_own_fraction", "[lifelong]") {
  SubmapTrimmerOptions o;
  o.min_own_fraction = 0.3;
  o.keep_newest = 1;
  SubmapTrimmer t(o);
  const OccupancyMap room = knownGrid(10, 4);  // 20 x 8 coarse cells
  t.addSubmap(0, t.footprint(room));
  t.addSubmap(1, t.footprint(room));
  // Submap 1 shifted 6 m along x: submap 0 keeps 6/10 of its cells: stays.
  CHECK(t.trim({{0, Pose2()}, {1, Pose2(6, 0, 0)}}, {}).empty());
  // Shifted 8 m... 0 still owns the 8 m not covered; shifted 2 m it owns 2/10 < 0.3: trimmed.
  CHECK(t.trim({{0, Pose2()}, {1, Pose2(8, 0, 0)}}, {}).empty());
  CHECK(t.trim({{0, Pose2()}, {1, Pose2(2, 0, 0)}}, {}) == std::vector<int>{0});
}

TEST_CASE("trimmer options out of range are refused by name", "[lifelong]") {
  SubmapTrimmerOptions o;
  o.cell_size = 0;
  CHECK_THROWS_WITH(SubmapTrimmer(o), Catch::StartsWith("cell_size"));
  o = {};
  o.min_own_fraction = 1.5;
  CHECK_THROWS_WITH(SubmapTrimmer(o), Catch::StartsWith("min_own_fraction"));
  o = {};
  o.keep_newest = 0;
  CHECK_THROWS_WITH(SubmapTrimmer(o), Catch::StartsWith("keep_newest"));
}

TEST_CASE("a removed submap leaves the graph connected and later constraints naming it refused",
          "[lifelong]") {
  SubmapGraph g;
  // Four submaps 5 m apart in a row, chained by exact hand-overs.
  g.addSubmap(0, Pose2());
  for (int i = 0; i < 3; ++i) g.addConstraint(handOver(i, i + 1, Pose2(5, 0, 0)));
  REQUIRE(g.nodes() == 4);
  CHECK(g.removeSubmap(1));
  CHECK(g.nodes() == 3);
  CHECK(g.edges() == 2);  // 0 - 2 (chained) and 2 - 3
  CHECK(g.removed(1));
  g.optimize();
  CHECK(g.pose(2).x == Approx(10.0));
  CHECK(g.pose(3).x == Approx(15.0));
  auto late = handOver(1, 3, Pose2(10, 0, 0));
  late.revisit = true;
  CHECK(g.addConstraint(late) == SubmapGraph::Outcome::kRejected);
  CHECK_THAT(g.lastError(), Catch::Contains("removed from the map"));
  CHECK(!g.removeSubmap(0));
  CHECK_THAT(g.lastError(), Catch::Contains("anchors"));
  CHECK(!g.removeSubmap(42));
  CHECK(g.pending() == 0);
}
