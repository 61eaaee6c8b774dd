// joinShards: shards of one trajectory, each tracked in its own frame and clock, placed back in
// shard 0's frame by the frames they share; lost frames, missing overlap and bad poses refused
// by name.
#include <tessera/visual_slam/shard_join.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

using tessera::Pose3;
using tessera::visual_slam::joinShards;
using tessera::visual_slam::ShardFramePose;
using tessera::visual_slam::ShardTrack;

namespace {

/// The true camera-to-world of frame i: a curving, climbing, turning path.
Pose3 truePose(int i) {
  const double s = 0.1 * i;
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.2 * s, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(0.05 * s, Eigen::Vector3d::UnitX()));
  return {{std::cos(s) * 2.0, std::sin(s) * 1.5, 0.02 * i}, q};
}

constexpr std::int64_t kFrameNs = 33'333'333;

/// Frames [first, last] as a shard tracks them: relative to its first frame, stamps from 0.
ShardTrack shard(int first, int last) {
  ShardTrack t;
  t.first_frame = static_cast<std::uint32_t>(first);
  const Pose3 origin_inv = truePose(first).inverse();
  for (int i = first; i <= last; ++i)
    t.poses.push_back(
        {static_cast<std::uint32_t>(i), (i - first) * kFrameNs, origin_inv * truePose(i)});
  return t;
}

double distance(const Pose3& a, const Pose3& b) {
  return (a.t - b.t).norm() + a.q.angularDistance(b.q);
}

}  // namespace

TEST_CASE("joinShards places every shard in shard 0's frame and clock",
          "[visual_slam][shard_join]") {
  const std::vector<ShardTrack> shards = {shard(0, 14), shard(10, 29), shard(25, 40)};
  const auto placed = joinShards(shards);
  REQUIRE(placed.size() == 3);
  CHECK(placed[0].join_frame == 0);
  CHECK(placed[1].join_frame == 10);
  CHECK(placed[2].join_frame == 25);
  const Pose3 world_inv = truePose(0).inverse();  // shard 0's frame = frame 0's camera
  for (std::size_t k = 0; k < shards.size(); ++k) {
    CHECK(placed[k].first_frame == shards[k].first_frame);
    for (const auto& p : shards[k].poses) {
      CHECK(distance(placed[k].world_from_shard * p.pose, world_inv * truePose(p.frame)) < 1e-9);
      CHECK(p.stamp_ns + placed[k].stamp_offset_ns == p.frame * kFrameNs);
    }
  }
}

TEST_CASE("joinShards joins on the next frame both shards tracked when one was lost",
          "[visual_slam][shard_join]") {
  std::vector<ShardTrack> shards = {shard(0, 14), shard(10, 29)};
  // Shard 0 lost frames 10 and 11, shard 1 lost frame 12 (and its first frame).
  auto& a = shards[0].poses;
  a.erase(a.begin() + 10, a.begin() + 12);
  auto& b = shards[1].poses;
  b.erase(b.begin() + 2);
  b.erase(b.begin());
  const auto placed = joinShards(shards);
  CHECK(placed[1].join_frame == 13);
  const Pose3 world_inv = truePose(0).inverse();
  for (const auto& p : shards[1].poses)
    CHECK(distance(placed[1].world_from_shard * p.pose, world_inv * truePose(p.frame)) < 1e-9);
}

TEST_CASE("joinShards refuses shards it cannot join, naming the shard",
          "[visual_slam][shard_join]") {
  using Catch::Matchers::Contains;
  CHECK_THROWS_WITH(joinShards({}), Contains("no shards"));
  CHECK_THROWS_WITH(
      joinShards({shard(0, 9), shard(12, 20)}),
      Contains("shard 1 shares no tracked frame with shard 0") && Contains("overlap"));
  CHECK_THROWS_WITH(joinShards({shard(10, 20), shard(5, 15)}),
                    Contains("shard 1 starts at frame 5"));
  ShardTrack empty;
  empty.first_frame = 8;
  CHECK_THROWS_WITH(joinShards({shard(0, 9), empty}), Contains("shard 1 tracked no frame"));
  std::vector<ShardTrack> nan = {shard(0, 9), shard(8, 15)};
  nan[1].poses[3].pose.t.x() = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(joinShards(nan), Contains("shard 1: the pose of frame 11 is not finite"));
  std::vector<ShardTrack> inf = {shard(0, 9)};
  inf[0].poses[0].pose.q.w() = std::numeric_limits<double>::infinity();
  CHECK_THROWS_AS(joinShards(inf), std::invalid_argument);
}
