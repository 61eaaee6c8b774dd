// OctoMapBuilder: log-odds clamping, a synthetic wall (occupied at the wall, free in front,
// unknown behind) for each insertion method, the background rebuild after keyframes move, .bt
// round trip and bad input.
#include <tessera/mapping3d/octomap_builder.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <limits>
#include <memory>
#include <thread>
#include <utility>
#include <vector>

#include "../../shared_data.hpp"
#include "mapping3d_fixtures.hpp"

using Catch::Matchers::Contains;
using namespace tessera::mapping3d;
using tessera::test::mapping3d::smallCamera;
using tessera::test::mapping3d::wallFrame;

namespace {

// Voxel centres at 5 cm: k * 0.05 + 0.025.
Eigen::Isometry3d at(double x, double y, double z) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(x, y, z);
  return pose;
}

PointCloud onePoint(float x, float y, float z) {
  PointCloud c;
  c.points.emplace_back(x, y, z);
  return c;
}

PointCloud wallCloud(double z) {
  KeyframeCloudOptions options;
  options.stride = 1;
  options.voxel_leaf = 0;
  return makeKeyframeCloud(smallCamera(), wallFrame(smallCamera(), z), options);
}

// A map with the wall at 2.02 m seen from the origin.
std::unique_ptr<OctoMapBuilder> wallMap(const OctoMapOptions& options) {
  auto map = std::make_unique<OctoMapBuilder>(options);
  map->insert(wallCloud(2.02), Eigen::Isometry3d::Identity());
  return map;
}

// Every voxel's log-odds of two maps agree over the box the test clouds reach.
void requireSameLeaves(const OctoMapBuilder& a, const OctoMapBuilder& b) {
  for (double x = -1.0; x <= 1.5; x += 0.05)
    for (double y = -0.3; y <= 0.6; y += 0.05)
      for (double z = -0.5; z <= 3.5; z += 0.05) {
        const Eigen::Vector3d p(x + 0.025, y + 0.025, z + 0.025);
        const auto la = a.logOdds(p), lb = b.logOdds(p);
        REQUIRE(la.has_value() == lb.has_value());
        if (la) REQUIRE(*la == Approx(*lb).margin(1e-6));
      }
  const OctoMapStats sa = a.stats(), sb = b.stats();
  CHECK(sa.leaves == sb.leaves);
  CHECK(sa.occupied_leaves == sb.occupied_leaves);
  CHECK(sa.points_inserted == sb.points_inserted);
}

}  // namespace

TEST_CASE("octomap log-odds saturate at the clamping thresholds", "[mapping3d][octomap]") {
  OctoMapOptions options;
  options.log_odds_hit = 1.0;
  options.log_odds_miss = -0.5;
  options.log_odds_min = -1.8;
  options.log_odds_max = 3.0;
  options.max_range = 0;
  OctoMapBuilder map(options);
  const Eigen::Vector3d hit(0.025, 0.025, 1.025), crossed(0.025, 0.025, 0.525);
  CHECK(map.occupancy(hit) == Occupancy::kUnknown);
  // The point 1 m straight ahead of a camera at a voxel centre: one hit, misses on the way.
  const auto point = onePoint(0, 0, 1);
  const auto origin = at(0.025, 0.025, 0.025);
  map.insert(point, origin);
  CHECK(*map.logOdds(hit) == Approx(1.0).margin(1e-4));
  CHECK(*map.logOdds(crossed) == Approx(-0.5).margin(1e-4));
  map.insert(point, origin);
  CHECK(*map.logOdds(hit) == Approx(2.0).margin(1e-4));
  for (int i = 0; i < 20; ++i) map.insert(point, origin);
  // L = clamp(L + l_z, l_min, l_max): 22 hits stop at l_max, 22 misses at l_min.
  CHECK(*map.logOdds(hit) == Approx(3.0).margin(1e-4));
  CHECK(*map.logOdds(crossed) == Approx(-1.8).margin(1e-4));
  CHECK(map.occupancy(hit) == Occupancy::kOccupied);
  CHECK(map.occupancy(crossed) == Occupancy::kFree);
  // One contrary observation moves a saturated voxel by one step only.
  map.insert(onePoint(0, 0, 2), origin);
  CHECK(*map.logOdds(hit) == Approx(2.5).margin(1e-4));
  const auto s = map.stats();
  CHECK(s.clouds_inserted == 23);
  CHECK(s.points_inserted == 23);
}

TEST_CASE("a wall is occupied where it is, free in front and unknown behind",
          "[mapping3d][octomap]") {
  for (const auto& [name, method] : optionNames(InsertMethod{})) {
    CAPTURE(name);
    OctoMapOptions options;
    options.method = method;
    const auto map_ptr = wallMap(options);
    const auto& map = *map_ptr;
    CHECK(map.occupancy({0.025, 0.025, 2.025}) == Occupancy::kOccupied);
    CHECK(map.occupancy({-0.475, 0.325, 2.025}) == Occupancy::kOccupied);
    CHECK(map.occupancy({0.025, 0.025, 1.025}) == Occupancy::kFree);
    CHECK(map.occupancy({0.025, 0.025, 0.225}) == Occupancy::kFree);
    CHECK(map.occupancy({0.025, 0.025, 2.525}) == Occupancy::kUnknown);
    CHECK(map.occupancy({3.025, 0.025, 1.025}) == Occupancy::kUnknown);  // outside the view
    const auto s = map.stats();
    CHECK(s.occupied_leaves > 100);
    CHECK(s.free_leaves > s.occupied_leaves);
    CHECK(s.memory_bytes > 0);
    CHECK(s.points_inserted == wallCloud(2.02).size());
  }
  SECTION("max_range cuts rays: a wall beyond it is not marked") {
    OctoMapOptions options;
    options.max_range = 1.5;
    const auto map = wallMap(options);
    CHECK(map->occupancy({0.025, 0.025, 2.025}) == Occupancy::kUnknown);
    CHECK(map->occupancy({0.025, 0.025, 1.025}) == Occupancy::kFree);
  }
  SECTION("lazy evaluation gives the same map") {
    OctoMapOptions options;
    options.lazy_eval = false;
    const auto eager = wallMap(options);
    const auto lazy = wallMap({});
    CHECK(lazy->stats().occupied_leaves == eager->stats().occupied_leaves);
    CHECK(lazy->stats().leaves == eager->stats().leaves);
    CHECK(lazy->occupancy({0.025, 0.025, 2.025}) == Occupancy::kOccupied);
  }
  SECTION("downsampling before insertion keeps the wall") {
    OctoMapOptions options;
    options.downsample_leaf = 0.05;
    const auto map = wallMap(options);
    CHECK(map->occupancy({0.025, 0.025, 2.025}) == Occupancy::kOccupied);
    CHECK(map->stats().points_inserted < wallCloud(2.02).size());
  }
}

TEST_CASE("octomap prune_period changes neither the leaves nor their log-odds",
          "[mapping3d][octomap]") {
  // The same seven clouds (a wall seen from seven places) into a map that updates its inner
  // nodes after every cloud and into one that does so every third cloud.
  OctoMapOptions every, third;
  every.prune_period = 1;
  third.prune_period = 3;
  OctoMapBuilder a(every), b(third);
  const PointCloud wall = wallCloud(2.02);
  for (int i = 0; i < 7; ++i) {
    const Eigen::Isometry3d pose = at(0.05 * i, -0.03 * i, 0.02 * i);
    a.insert(wall, pose);
    b.insert(wall, pose);
  }
  requireSameLeaves(a, b);
  CHECK(a.stats().memory_bytes == b.stats().memory_bytes);
  OctoMapOptions bad;
  bad.prune_period = 0;
  CHECK_THROWS_WITH(OctoMapBuilder(bad), Contains("prune_period"));
  bad = {};
  bad.rebuild_threads = -1;
  CHECK_THROWS_WITH(OctoMapBuilder(bad), Contains("rebuild_threads"));
}

TEST_CASE("octomap rebuild re-inserts moved keyframes and keeps newer clouds",
          "[mapping3d][octomap]") {
  OctoMapBuilder map;
  auto wall = std::make_shared<const PointCloud>(wallCloud(2.02));
  map.insert(*wall, Eigen::Isometry3d::Identity());
  REQUIRE(map.occupancy({0.025, 0.025, 2.025}) == Occupancy::kOccupied);

  // The pose graph moved the keyframe 0.5 m back: the wall is now at z = 1.52.
  map.rebuild({PlacedCloud{wall, at(0, 0, -0.5)}});
  // A cloud inserted while the rebuild runs must survive the swap.
  map.insert(onePoint(0, 0, 1), at(1.025, 1.025, 0.025));
  map.waitForRebuild();
  CHECK_FALSE(map.rebuilding());
  CHECK(map.occupancy({0.025, 0.025, 1.525}) == Occupancy::kOccupied);
  CHECK(map.occupancy({0.025, 0.025, 2.025}) == Occupancy::kUnknown);
  CHECK(map.occupancy({1.025, 1.025, 1.025}) == Occupancy::kOccupied);
  const auto s = map.stats();
  CHECK(s.rebuilds_completed == 1);
  CHECK(s.clouds_inserted == 2);

  SECTION("waitForRebuild serves the newest request") {
    map.rebuild({PlacedCloud{wall, at(0, 0, 0.5)}, PlacedCloud{wall, at(0, 0, 0.5)}});
    map.rebuild({PlacedCloud{wall, at(0, 0, 1.0)}});
    map.waitForRebuild();
    CHECK(map.occupancy({0.025, 0.025, 3.025}) == Occupancy::kOccupied);
    CHECK(map.occupancy({0.025, 0.025, 2.525}) == Occupancy::kFree);
    CHECK(map.stats().clouds_inserted == 1);
  }
}

TEST_CASE("octomap rebuild gives the tree that inserting its clouds one by one gives",
          "[mapping3d][octomap]") {
  // Overlapping views so that clouds update the same voxels (order and clamping matter).
  const auto wall = std::make_shared<const PointCloud>(wallCloud(2.02));
  std::vector<PlacedCloud> keyframes;
  for (int i = 0; i < 13; ++i) keyframes.push_back({wall, at(0.04 * i, 0.02 * (i % 3), -0.03 * i)});
  const auto [method, threads] =
      GENERATE(std::pair{InsertMethod::kDiscretized, 0}, std::pair{InsertMethod::kDiscretized, 1},
               std::pair{InsertMethod::kPointCloud, 2}, std::pair{InsertMethod::kRays, 2});
  CAPTURE(methodName(method), threads);
  OctoMapOptions options;
  options.method = method;
  options.rebuild_threads = threads;
  options.prune_period = 4;
  OctoMapBuilder inserted(options), rebuilt(options);
  for (const auto& k : keyframes) inserted.insert(*k.cloud, k.camera_to_world);
  rebuilt.insert(*wall, at(0, 0, 1));  // replaced by the rebuild
  rebuilt.rebuild(keyframes);
  rebuilt.waitForRebuild();
  REQUIRE(rebuilt.stats().rebuilds_completed == 1);
  requireSameLeaves(inserted, rebuilt);
}

TEST_CASE("octomap rebuild requested while one runs waits for it and keeps every cloud",
          "[mapping3d][octomap]") {
  const auto wall = std::make_shared<const PointCloud>(wallCloud(2.02));
  std::vector<PlacedCloud> long_request(60, PlacedCloud{wall, at(0, 0, 0.5)});
  OctoMapBuilder map;
  map.rebuild(long_request);
  map.insert(*wall, at(0, 0, 0.25));  // while the first rebuild runs: in no later snapshot
  map.rebuild({PlacedCloud{wall, at(0, 0, 1.0)}, PlacedCloud{wall, at(0, 0, 0.25)}});
  map.insert(onePoint(0, 0, 1), at(1.025, 1.025, 0.025));  // after both requests
  // No waitForRebuild: the first rebuild must run to its end, then the second one.
  for (int i = 0; i < 60000 && map.rebuilding(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  REQUIRE_FALSE(map.rebuilding());
  const OctoMapStats s = map.stats();
  CHECK(s.rebuilds_abandoned == 0);
  CHECK(s.rebuilds_completed >= 1);
  CHECK(s.clouds_inserted == 3);
  CHECK(map.occupancy({0.025, 0.025, 3.025}) == Occupancy::kOccupied);
  CHECK(map.occupancy({0.025, 0.025, 2.275}) == Occupancy::kOccupied);
  CHECK(map.occupancy({0.025, 0.025, 2.525}) == Occupancy::kFree);
  CHECK(map.occupancy({1.025, 1.025, 1.025}) == Occupancy::kOccupied);
}

TEST_CASE("octomap .bt files round-trip and bad input is named", "[mapping3d][octomap]") {
  const auto dir = tessera::test::scratchDir("mapping3d_bt");
  const auto map_ptr = wallMap({});
  auto& map = *map_ptr;
  map.writeBinary(dir / "map.bt");
  REQUIRE(std::filesystem::file_size(dir / "map.bt") > 100);
  OctoMapBuilder back;
  back.readBinary(dir / "map.bt");
  CHECK(back.occupancy({0.025, 0.025, 2.025}) == Occupancy::kOccupied);
  CHECK(back.occupancy({0.025, 0.025, 1.025}) == Occupancy::kFree);
  CHECK(back.occupancy({0.025, 0.025, 2.525}) == Occupancy::kUnknown);
  CHECK(back.stats().occupied_leaves == map.stats().occupied_leaves);

  std::ofstream(dir / "junk.bt") << "# Octomap OcTree binary file\nnot really\n";
  CHECK_THROWS_WITH(back.readBinary(dir / "junk.bt"), Contains("junk.bt"));
  CHECK_THROWS_WITH(back.readBinary(dir / "missing.bt"), Contains("missing.bt"));
  OctoMapOptions coarse;
  coarse.resolution = 0.1;
  CHECK_THROWS_WITH(OctoMapBuilder(coarse).readBinary(dir / "map.bt"), Contains("resolution"));
  CHECK_THROWS_WITH(map.writeBinary(dir / "no_such_dir" / "x.bt"), Contains("x.bt"));

  Eigen::Isometry3d nan_pose = Eigen::Isometry3d::Identity();
  nan_pose.translation().z() = std::nan("");
  CHECK_THROWS_WITH(map.insert(onePoint(0, 0, 1), nan_pose), Contains("pose"));
  CHECK_THROWS_WITH(map.rebuild({PlacedCloud{nullptr, Eigen::Isometry3d::Identity()}}),
                    Contains("cloud"));
  // Non-finite points are skipped, not inserted.
  map.insert(onePoint(std::nanf(""), 0, 1), Eigen::Isometry3d::Identity());
  OctoMapOptions bad;
  bad.log_odds_max = -3;
  CHECK_THROWS_WITH(OctoMapBuilder{bad}, Contains("log_odds_occupied"));
  bad = {};
  bad.resolution = 0;
  CHECK_THROWS_WITH(OctoMapBuilder{bad}, Contains("resolution"));
  bad = {};
  bad.log_odds_miss = 0.2;
  CHECK_THROWS_WITH(OctoMapBuilder{bad}, Contains("log_odds_miss"));
}

namespace occupied_voxels_test {

// Largest per-axis distance from `p` to the nearest point of `points`.
double nearestInf(const Eigen::Vector3f& p, const std::vector<Eigen::Vector3f>& points) {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& q : points)
    best = std::min(best, static_cast<double>((p - q).lpNorm<Eigen::Infinity>()));
  return best;
}

// The wall cloud of the tests above in the world frame, seen from `pose`.
std::vector<Eigen::Vector3f> worldPoints(const PointCloud& cloud, const Eigen::Isometry3d& pose) {
  std::vector<Eigen::Vector3f> out;
  for (const auto& p : cloud.points) out.push_back(pose.cast<float>() * p);
  return out;
}

}  // namespace occupied_voxels_test

TEST_CASE("octomap occupied voxel centres lie on the inserted points", "[mapping3d][octomap]") {
  using occupied_voxels_test::nearestInf;
  using occupied_voxels_test::worldPoints;
  OctoMapOptions options;
  options.prune_period = 1000;  // inner nodes not updated by the insertion itself
  OctoMapBuilder map(options);
  const OccupiedVoxels none = map.occupiedVoxels(1000);
  CHECK(none.centres.empty());
  CHECK(none.voxel_size == Approx(0.05));

  const PointCloud wall = wallCloud(2.02);
  map.insert(wall, Eigen::Isometry3d::Identity());
  const auto points = worldPoints(wall, Eigen::Isometry3d::Identity());
  const OccupiedVoxels all = map.occupiedVoxels(1'000'000);
  CHECK(all.depth == 16);
  CHECK(all.voxel_size == Approx(0.05));
  CHECK(all.revision == map.revision());
  REQUIRE(all.centres.size() == map.stats().occupied_leaves);
  for (const auto& c : all.centres) {
    REQUIRE(c.allFinite());
    REQUIRE(nearestInf(c, points) <= 0.025 + 1e-4);
    REQUIRE(map.occupancy(c.cast<double>()) == Occupancy::kOccupied);
  }
  // Every point's voxel is there.
  for (const auto& p : points) REQUIRE(nearestInf(p, all.centres) <= 0.025 + 1e-4);
  CHECK(map.occupiedVoxels(0).centres.empty());

  SECTION("a small maximum gives fewer points at a coarser voxel") {
    OctoMapBuilder fresh(options);  // the inner nodes of a tree nobody finalized yet
    fresh.insert(wall, Eigen::Isometry3d::Identity());
    for (const std::size_t max_points : {all.centres.size() - 1, all.centres.size() / 5,
                                         all.centres.size() / 50, std::size_t{10}}) {
      CAPTURE(max_points);
      const OccupiedVoxels coarse = fresh.occupiedVoxels(max_points);
      CHECK(coarse.depth < 16);
      CHECK(coarse.voxel_size == Approx(0.05 * std::pow(2.0, 16 - coarse.depth)));
      REQUIRE_FALSE(coarse.centres.empty());
      CHECK(coarse.centres.size() <= max_points);
      const double half = 0.5 * coarse.voxel_size + 1e-4;
      for (const auto& c : coarse.centres) REQUIRE(nearestInf(c, points) <= half);
      for (const auto& p : points) REQUIRE(nearestInf(p, coarse.centres) <= half);
    }
    // One voxel at least: the root when even the eight octants are too many.
    const OccupiedVoxels one = fresh.occupiedVoxels(1);
    CHECK(one.centres.size() == 1);
    CHECK(one.depth == 0);
  }
  SECTION("the revision follows changes") {
    const std::uint64_t r = map.revision();
    map.occupiedVoxels(10);
    CHECK(map.revision() == r);
    map.insert(onePoint(0, 0, 1), Eigen::Isometry3d::Identity());
    CHECK(map.revision() > r);
  }
}

TEST_CASE("octomap occupied voxels during and after a rebuild", "[mapping3d][octomap]") {
  using occupied_voxels_test::nearestInf;
  using occupied_voxels_test::worldPoints;
  OctoMapBuilder map;
  auto wall = std::make_shared<const PointCloud>(wallCloud(2.02));
  std::vector<PlacedCloud> keyframes;
  for (int i = 0; i < 30; ++i) {
    map.insert(*wall, at(0.01 * i, 0, 0));
    keyframes.push_back({wall, at(0.01 * i, 0, 0.5)});  // every keyframe 0.5 m farther forward
  }
  const std::uint64_t before = map.revision();
  map.rebuild(keyframes);
  // Served meanwhile: the old tree, or the new one once it swapped in, never a mix.
  while (map.rebuilding()) {
    const OccupiedVoxels v = map.occupiedVoxels(100'000);
    REQUIRE_FALSE(v.centres.empty());
    const float z = v.centres.front().z();
    for (const auto& c : v.centres) REQUIRE(std::abs(c.z() - z) < 0.051f);
  }
  map.waitForRebuild();
  const OccupiedVoxels after = map.occupiedVoxels(100'000);
  CHECK(after.revision > before);
  const auto moved = worldPoints(*wall, at(0, 0, 0.5));
  REQUIRE_FALSE(after.centres.empty());
  for (const auto& c : after.centres) REQUIRE(std::abs(c.z() - 2.525f) < 0.026f);
  CHECK(nearestInf(moved.front(), after.centres) <= 0.025 + 1e-4);
}
