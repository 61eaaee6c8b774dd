// The rgbd_mapper actor through the mock-mailbox harness: hand-made keyframes of a wall 2 m in
// front of the camera go into the cloud map and the OctoMap where expected; a KeyframePoses that
// moves a keyframe moves its points in the saved cloud and rebuilds the OctoMap; broken keyframes
// and pose entries are counted and skipped.
#include <tessera/mapping3d/cloud_map.hpp>
#include <tessera/mapping3d/octomap_builder.hpp>
#include <tessera/mapping3d/rgbd_mapper_actor.hpp>
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

#include "../../shared_data.hpp"

using namespace tessera;
using namespace tessera::mapping3d;
namespace fs = std::filesystem;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::int64_t summaryInt(ActorHarness& h, const std::string& key) {
  Summary s;
  h.actor().summarize(s);
  const auto it = s.find(key);
  return it == s.end() ? -1 : std::get<std::int64_t>(it->second);
}

Pose3 translation(double x, double y, double z) {
  return {{x, y, z}, Eigen::Quaterniond::Identity()};
}

// A keyframe message as rgbd_front_end writes one (no features needed by the mapper): a 640 x 480
// camera whose depth, kept every 8th pixel (80 x 60 samples), sees a wall at `depth_m`.
void pushKeyframe(ActorHarness& h, std::uint32_t id, const Pose3& pose, double depth_m = 2.0,
                  const std::function<void(msg::Keyframe::Builder)>& spoil = {}) {
  h.push<msg::Keyframe>("keyframes", [&](msg::Keyframe::Builder b) {
    setHeader(b.initHeader(), 1000 * id, "world", id);
    b.setId(id);
    writePose(b.initPose(), pose);
    auto in = b.initIntrinsics();
    in.setFx(525);
    in.setFy(525);
    in.setCx(319.5);
    in.setCy(239.5);
    in.setWidth(640);
    in.setHeight(480);
    b.setDepthStep(8);
    b.setDepthWidth(80);
    b.setDepthHeight(60);
    b.setDepthScale(1000);
    auto depth = b.initDepth(2 * 80 * 60);
    const auto units = static_cast<std::uint16_t>(std::lround(depth_m * 1000));
    for (std::size_t i = 0; i < 80 * 60; ++i) {
      depth[2 * i] = static_cast<std::uint8_t>(units & 0xff);
      depth[2 * i + 1] = static_cast<std::uint8_t>(units >> 8);
    }
    if (spoil) spoil(b);
  });
  h.runUntilIdle();
}

void pushPoses(ActorHarness& h, const std::vector<std::pair<std::uint32_t, Pose3>>& poses) {
  h.push<msg::KeyframePoses>("keyframe_poses", [&](msg::KeyframePoses::Builder b) {
    setHeader(b.initHeader(), 0, "world", 0);
    auto list = b.initPoses(static_cast<unsigned>(poses.size()));
    for (unsigned i = 0; i < poses.size(); ++i) {
      list[i].setId(poses[i].first);
      writePose(list[i].initPose(), poses[i].second);
    }
  });
  h.runUntilIdle();
}

// Points of `cloud` within `radius` of `p`.
std::size_t near(const PointCloud& cloud, const Eigen::Vector3f& p, float radius) {
  std::size_t n = 0;
  for (const auto& q : cloud.points) n += (q - p).norm() < radius ? 1 : 0;
  return n;
}

}  // namespace

TEST_CASE("rgbd_mapper maps keyframes and moves them with KeyframePoses",
          "[actors][mapping3d][rgbd_mapper]") {
  const fs::path out = test::scratchDir("rgbd_mapper");
  ActorHarness h(std::make_unique<RgbdMapperActor>(RgbdMapperOptions{}), out.string());
  auto& mapper = static_cast<RgbdMapperActor&>(h.actor());

  pushKeyframe(h, 0, translation(0, 0, 0));
  pushKeyframe(h, 1, translation(1, 0, 0));
  CHECK(summaryInt(h, "keyframes_mapped") == 2);
  CHECK(mapper.cloudMap().keyframeCount() == 2);
  // The wall spans x in about [-1.22, 1.22] m at z = 2 m in each camera.
  const PointCloud before = mapper.cloudMap().assemble();
  REQUIRE(before.size() > 1000);
  CHECK(std::all_of(before.points.begin(), before.points.end(),
                    [](const Eigen::Vector3f& p) { return std::abs(p.z() - 2.0f) < 0.02f; }));
  CHECK(near(before, {2.0f, 0, 2.0f}, 0.05f) > 0);  // keyframe 1 alone sees x = 2
  CHECK(mapper.octomap().occupancy({0, 0, 2.01}) == Occupancy::kOccupied);
  CHECK(mapper.octomap().occupancy({0, 0, 1.0}) == Occupancy::kFree);

  // Moves below the thresholds change nothing.
  pushPoses(h, {{0, translation(0, 0, 0)}, {1, translation(1.002, 0, 0)}});
  CHECK(summaryInt(h, "rebuilds") == 0);
  CHECK(mapper.cloudMap().keyframe(1).camera_to_world.translation().x() == 1.0);

  // Keyframe 1 moves 0.5 m forward: its wall is now at z = 2.5.
  pushPoses(h, {{0, translation(0, 0, 0)}, {1, translation(1, 0, 0.5)}});
  CHECK(summaryInt(h, "rebuilds") == 1);
  CHECK(summaryInt(h, "keyframes_moved") == 1);
  h.stop();
  CHECK(summaryInt(h, "rebuilds_completed") == 1);

  const PointCloud saved = readPcd(out / "cloud.pcd");
  CHECK(readPly(out / "cloud.ply").size() == saved.size());
  CHECK(near(saved, {2.0f, 0, 2.5f}, 0.05f) > 0);
  CHECK(near(saved, {2.0f, 0, 2.0f}, 0.1f) == 0);
  CHECK(near(saved, {0, 0, 2.0f}, 0.05f) > 0);  // keyframe 0 stayed

  OctoMapBuilder loaded;
  REQUIRE_NOTHROW(loaded.readBinary(out / "map.bt"));
  CHECK(loaded.occupancy({2.0, 0, 2.51}) == Occupancy::kOccupied);
  CHECK(loaded.occupancy({2.0, 0, 2.01}) != Occupancy::kOccupied);
  CHECK(mapper.octomap().occupancy({2.0, 0, 2.51}) == Occupancy::kOccupied);
  CHECK(summaryInt(h, "octomap_leaves") > 0);
}

TEST_CASE("rgbd_mapper drops the keyframes the graph trimmed and rebuilds without them",
          "[actors][mapping3d][rgbd_mapper][lifelong]") {
  const fs::path out = test::scratchDir("rgbd_mapper_trim");
  ActorHarness h(std::make_unique<RgbdMapperActor>(RgbdMapperOptions{}), out.string());
  auto& mapper = static_cast<RgbdMapperActor&>(h.actor());
  for (std::uint32_t id = 0; id < 4; ++id) pushKeyframe(h, id, translation(3.0 * id, 0, 0));
  CHECK(mapper.octomap().occupancy({3.0, 0, 2.01}) == Occupancy::kOccupied);
  // The graph holds 0 and 2 (newest listed): 1 was trimmed; 3 is newer than the list, so stays.
  pushPoses(h, {{0, translation(0, 0, 0)}, {2, translation(6, 0, 0)}});
  CHECK(summaryInt(h, "keyframes_dropped") == 1);
  CHECK(summaryInt(h, "keyframes_held") == 3);
  CHECK_FALSE(mapper.cloudMap().contains(1));
  CHECK(mapper.cloudMap().contains(3));
  CHECK(summaryInt(h, "rebuilds") == 1);
  // The same list again drops nothing more.
  pushPoses(h, {{0, translation(0, 0, 0)}, {2, translation(6, 0, 0)}});
  CHECK(summaryInt(h, "keyframes_dropped") == 1);
  CHECK(summaryInt(h, "rebuilds") == 1);
  h.stop();
  const PointCloud saved = readPcd(out / "cloud.pcd");
  CHECK(near(saved, {3.0f, 0, 2.0f}, 0.1f) == 0);  // only keyframe 1 saw x = 3
  CHECK(near(saved, {0, 0, 2.0f}, 0.05f) > 0);
  CHECK(near(saved, {9.0f, 0, 2.0f}, 0.05f) > 0);
  CHECK(mapper.octomap().occupancy({3.0, 0, 2.01}) != Occupancy::kOccupied);
  CHECK(mapper.octomap().occupancy({6.0, 0, 2.01}) == Occupancy::kOccupied);
}

TEST_CASE("rgbd_mapper keeps a listed keyframe whose pose entry is unreadable",
          "[actors][mapping3d][rgbd_mapper][lifelong]") {
  // A NaN pose is a bad entry, not a keyframe the graph let go: its cloud stays.
  ActorHarness h(std::make_unique<RgbdMapperActor>(RgbdMapperOptions{}));
  auto& mapper = static_cast<RgbdMapperActor&>(h.actor());
  for (std::uint32_t id = 0; id < 3; ++id) pushKeyframe(h, id, translation(3.0 * id, 0, 0));
  pushPoses(h,
            {{0, translation(0, 0, 0)}, {1, translation(kNaN, 0, 0)}, {2, translation(6, 0, 0.5)}});
  CHECK(summaryInt(h, "keyframes_held") == 3);
  CHECK(mapper.cloudMap().contains(1));
  CHECK(summaryInt(h, "poses_bad_pose") == 1);
  CHECK(summaryInt(h, "rebuilds") == 1);  // keyframe 2 moved
}

TEST_CASE("rgbd_mapper counts and skips bad keyframes and poses",
          "[actors][mapping3d][rgbd_mapper]") {
  ActorHarness h(std::make_unique<RgbdMapperActor>(RgbdMapperOptions{}));
  pushKeyframe(h, 0, translation(0, 0, 0), 2.0, [](msg::Keyframe::Builder b) {
    b.setDepthWidth(0);
    b.setDepthHeight(0);
    b.initDepth(0);
  });
  pushKeyframe(h, 1, translation(0, 0, 0), 2.0, [](msg::Keyframe::Builder b) {
    b.initDepth(100);  // not 80 x 60 x 2 bytes
  });
  pushKeyframe(h, 2, translation(0, 0, 0), 2.0, [](msg::Keyframe::Builder b) {
    b.getIntrinsics().setWidth(320);  // the block is not this image's at step 8
  });
  pushKeyframe(h, 3, translation(kNaN, 0, 0));
  pushKeyframe(h, 4, translation(0, 0, 0), 2.0,
               [](msg::Keyframe::Builder b) { b.getIntrinsics().setFx(0); });
  pushKeyframe(h, 5, translation(0, 0, 0), 2.0,
               [](msg::Keyframe::Builder b) { b.setDepthScale(kNaN); });
  pushKeyframe(h, 6, translation(0, 0, 0), 2.0, [](msg::Keyframe::Builder b) {
    b.getPose().setQw(0);  // a quaternion of zero length
  });
  pushKeyframe(h, 7, translation(0, 0, 0), 9.0);  // beyond max_depth: an empty cloud, kept
  pushKeyframe(h, 8, translation(0, 0, 0));
  pushKeyframe(h, 8, translation(0, 0, 0));  // the same id again

  CHECK(summaryInt(h, "keyframes_received") == 10);
  CHECK(summaryInt(h, "keyframes_mapped") == 2);
  CHECK(summaryInt(h, "keyframes_empty") == 1);
  CHECK(summaryInt(h, "keyframes_bad") == 8);
  CHECK(summaryInt(h, "keyframes_bad_no_depth") == 1);
  CHECK(summaryInt(h, "keyframes_bad_depth_size") == 2);
  CHECK(summaryInt(h, "keyframes_bad_pose") == 2);
  CHECK(summaryInt(h, "keyframes_bad_intrinsics") == 1);
  CHECK(summaryInt(h, "keyframes_bad_depth_scale") == 1);
  CHECK(summaryInt(h, "keyframes_bad_duplicate_id") == 1);

  // An unknown id and a NaN pose are skipped; the good entry still moves keyframe 8.
  pushPoses(
      h, {{42, translation(0, 0, 0)}, {7, translation(kNaN, 0, 0)}, {8, translation(0.5, 0, 0)}});
  CHECK(summaryInt(h, "poses_bad_unknown_id") == 1);
  CHECK(summaryInt(h, "poses_bad_pose") == 1);
  CHECK(summaryInt(h, "rebuilds") == 1);
  h.stop();  // no output directory: nothing written, no throw
  CHECK(summaryInt(h, "rebuilds_completed") == 1);
}

TEST_CASE("rgbd_mapper rejects bad options naming the key", "[actors][mapping3d][rgbd_mapper]") {
  RgbdMapperOptions o;
  o.octomap.resolution = 0;
  CHECK_THROWS_WITH(RgbdMapperActor(o), Catch::Contains("octomap.resolution"));
  o = {};
  o.cloud.voxel_leaf = -1;
  CHECK_THROWS_WITH(RgbdMapperActor(o), Catch::Contains("cloud.voxel_leaf"));
  o = {};
  o.move_threshold_m = kNaN;
  CHECK_THROWS_WITH(RgbdMapperActor(o), Catch::Contains("move_threshold_m"));
}

TEST_CASE("rgbd_mapper saves periodically with save_period_s", "[actors][mapping3d][rgbd_mapper]") {
  const fs::path out = test::scratchDir("rgbd_mapper_periodic");
  RgbdMapperOptions o;
  o.save_period_s = 1.0;
  o.ply_file = "";  // an empty name: that file is not written
  ActorHarness h(std::make_unique<RgbdMapperActor>(o), out.string());
  h.advance(kNanosPerSecond * 3 / 2);  // nothing mapped yet: nothing written
  CHECK_FALSE(fs::exists(out / "cloud.pcd"));
  pushKeyframe(h, 0, translation(0, 0, 0));
  h.advance(kNanosPerSecond);
  CHECK(fs::exists(out / "cloud.pcd"));
  CHECK(fs::exists(out / "map.bt"));
  CHECK_FALSE(fs::exists(out / "cloud.ply"));
  CHECK(summaryInt(h, "saves") == 1);
  h.stop();
  CHECK(summaryInt(h, "saves") == 2);
}

namespace map_cloud_preview_test {

// The points of a map_cloud message, checked to be what its fields say.
std::vector<Eigen::Vector3f> pointsOf(const Message<msg::PointCloud>& m) {
  const auto xyz = m->getXyz();
  REQUIRE(xyz.size() == 12 * std::size_t{m->getCount()});
  CHECK(m->getRgb().size() == 0);
  std::vector<Eigen::Vector3f> out;
  for (std::size_t i = 0; i < m->getCount(); ++i) {
    Eigen::Vector3f p;
    for (int k = 0; k < 3; ++k) {
      std::uint32_t bits = 0;
      for (int b = 0; b < 4; ++b)
        bits |= static_cast<std::uint32_t>(
                    xyz[12 * i + 4 * static_cast<std::size_t>(k) + static_cast<std::size_t>(b)])
                << (8 * b);
      p[k] = std::bit_cast<float>(bits);
    }
    out.push_back(p);
  }
  return out;
}

}  // namespace map_cloud_preview_test

TEST_CASE("rgbd_mapper publishes map_cloud every preview_period_s when the map changed",
          "[actors][mapping3d][rgbd_mapper][map_cloud]") {
  using map_cloud_preview_test::pointsOf;
  ActorHarness h(std::make_unique<RgbdMapperActor>(RgbdMapperOptions{}));  // 1 s, 100000 points
  h.advance(kNanosPerSecond * 3 / 2);  // an empty map: nothing to preview
  CHECK(h.publishedCount("map_cloud") == 0);
  pushKeyframe(h, 0, translation(0, 0, 0));
  pushKeyframe(h, 1, translation(1, 0, 0));
  CHECK(h.publishedCount("map_cloud") == 0);  // not before the period ends
  h.advance(kNanosPerSecond);
  auto clouds = h.published<msg::PointCloud>("map_cloud");
  REQUIRE(clouds.size() == 1);
  const auto& m = clouds[0];
  CHECK(std::string(m->getHeader().getFrameId().cStr()) == "world");
  CHECK(m->getVoxelSize() == Approx(0.05));
  const auto points = pointsOf(m);
  REQUIRE(points.size() > 500);
  for (const auto& p : points) {
    REQUIRE(p.allFinite());
    REQUIRE(std::abs(p.z() - 2.0f) < 0.06f);  // the wall, 2 m ahead of both keyframes
    REQUIRE(p.x() > -1.4f);
    REQUIRE(p.x() < 2.4f);
  }
  CHECK(static_cast<std::size_t>(m->getCount()) ==
        static_cast<RgbdMapperActor&>(h.actor()).octomap().stats().occupied_leaves);

  // Nothing changed: nothing republished, at the next periods or at stop.
  h.advance(3 * kNanosPerSecond);
  CHECK(h.publishedCount("map_cloud") == 1);
  // A new keyframe changes the map: one more at the next period.
  pushKeyframe(h, 2, translation(0, 0, 0.5));
  h.advance(kNanosPerSecond);
  clouds = h.published<msg::PointCloud>("map_cloud");
  REQUIRE(clouds.size() == 2);
  CHECK(clouds[1]->getHeader().getSeq() == clouds[0]->getHeader().getSeq() + 1);
  const auto more = pointsOf(clouds[1]);
  CHECK(std::any_of(more.begin(), more.end(),
                    [](const Eigen::Vector3f& p) { return std::abs(p.z() - 2.5f) < 0.06f; }));
  h.advance(kNanosPerSecond);
  h.stop();
  CHECK(h.publishedCount("map_cloud") == 2);
  CHECK(summaryInt(h, "previews") == 2);
}

TEST_CASE("rgbd_mapper map_cloud: coarser voxels beyond preview_max_points, off with period 0",
          "[actors][mapping3d][rgbd_mapper][map_cloud]") {
  using map_cloud_preview_test::pointsOf;
  SECTION("preview_max_points") {
    RgbdMapperOptions o;
    o.preview_max_points = 200;
    ActorHarness h(std::make_unique<RgbdMapperActor>(o));
    pushKeyframe(h, 0, translation(0, 0, 0));
    h.advance(kNanosPerSecond);
    const auto clouds = h.published<msg::PointCloud>("map_cloud");
    REQUIRE(clouds.size() == 1);
    CHECK(clouds[0]->getCount() <= 200);
    CHECK(clouds[0]->getCount() > 0);
    const double voxel = clouds[0]->getVoxelSize();
    CHECK(voxel > 0.09);
    // A power of two times the resolution.
    CHECK(std::log2(voxel / 0.05) == Approx(std::round(std::log2(voxel / 0.05))).margin(1e-4));
    for (const auto& p : pointsOf(clouds[0])) REQUIRE(std::abs(p.z() - 2.0f) < voxel);
  }
  SECTION("preview_period_s = 0: never, not even at stop") {
    RgbdMapperOptions o;
    o.preview_period_s = 0;
    ActorHarness h(std::make_unique<RgbdMapperActor>(o));
    pushKeyframe(h, 0, translation(0, 0, 0));
    h.advance(5 * kNanosPerSecond);
    h.stop();
    CHECK(h.publishedCount("map_cloud") == 0);
  }
  SECTION("the map at stop, after its last rebuild") {
    RgbdMapperOptions o;
    o.preview_period_s = 10;
    ActorHarness h(std::make_unique<RgbdMapperActor>(o));
    pushKeyframe(h, 0, translation(0, 0, 0));
    pushPoses(h, {{0, translation(0, 0, 0.5)}});
    h.stop();
    const auto clouds = h.published<msg::PointCloud>("map_cloud");
    REQUIRE(clouds.size() == 1);
    for (const auto& p : pointsOf(clouds[0])) REQUIRE(std::abs(p.z() - 2.5f) < 0.06f);
  }
}

TEST_CASE("rgbd_mapper rejects bad preview options naming the key",
          "[actors][mapping3d][rgbd_mapper][map_cloud]") {
  RgbdMapperOptions o;
  o.preview_period_s = -1;
  CHECK_THROWS_WITH(RgbdMapperActor(o), Catch::Contains("preview_period_s"));
  o = {};
  o.preview_period_s = std::numeric_limits<double>::infinity();
  CHECK_THROWS_WITH(RgbdMapperActor(o), Catch::Contains("preview_period_s"));
  o = {};
  o.preview_max_points = 0;
  CHECK_THROWS_WITH(RgbdMapperActor(o), Catch::Contains("preview_max_points"));
}
