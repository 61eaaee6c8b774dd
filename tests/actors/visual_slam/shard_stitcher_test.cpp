// shard_stitcher through the mock-mailbox harness: two shards' recordings (made here with the
// recording writer, as the batch's recorder makes them) become one keyframe / pose / ground-truth
// stream in shard 0's frame and clock; missing, damaged, mistyped, empty and non-finite
// recordings are refused by file name before anything is published.
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/recording.hpp>
#include <tessera/visual_slam/shard_stitcher_actor.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

#include "../../shared_data.hpp"

using namespace tessera;
using namespace tessera::visual_slam;
namespace fs = std::filesystem;

namespace shard_stitcher_test {

constexpr Nanos kFrameNs = 100'000'000;

/// The true camera-to-world of frame i.
Pose3 trueCamera(int i) {
  const double s = 0.1 * i;
  return {{s, 0.5 * std::sin(s), 0.01 * i},
          Eigen::Quaterniond(Eigen::AngleAxisd(0.3 * s, Eigen::Vector3d::UnitZ()))};
}

struct ShardSpec {
  int first = 0, last = 0;
  std::vector<int> keyframes;  // frame indices
  double nan_at = -1;          // frame whose pose is NaN
};

/// A shard's recording: poses relative to its first frame, stamps from 0, as a shard run has.
fs::path writeShard(const fs::path& dir, const std::string& name, const ShardSpec& s,
                    bool with_truth = true) {
  const fs::path path = dir / name;
  RecordingWriter w(
      path.string(),
      {{"keyframes", messageTypeOf<msg::Keyframe>().id, "Keyframe"},
       {"camera_pose", messageTypeOf<msg::PoseStamped3D>().id, "PoseStamped3D"},
       {"ground_truth", messageTypeOf<msg::GroundTruthPose3D>().id, "GroundTruthPose3D"}});
  const Pose3 origin_inv = trueCamera(s.first).inverse();
  std::uint32_t kf_id = 0;
  for (int i = s.first; i <= s.last; ++i) {
    const Nanos stamp = (i - s.first) * kFrameNs;
    Pose3 local = origin_inv * trueCamera(i);
    if (i == s.nan_at) local.t.x() = std::numeric_limits<double>::quiet_NaN();
    if (with_truth) {
      auto gt = makeMessage<msg::GroundTruthPose3D>([&](auto b) {
        b.initHeader().setStampNs(stamp);
        writePose(b.initPose(), trueCamera(i));
      });
      w.append(2, stamp, *gt.storage());
    }
    auto pose = makeMessage<msg::PoseStamped3D>([&](auto b) {
      b.initHeader().setStampNs(stamp);
      writePose(b.initPose(), local);
      b.setFrameIndex(static_cast<std::uint32_t>(i));
    });
    w.append(1, stamp, *pose.storage());
    if (std::count(s.keyframes.begin(), s.keyframes.end(), i)) {
      auto kf = makeMessage<msg::Keyframe>([&](auto b) {
        b.initHeader().setStampNs(stamp);
        b.setId(kf_id++);
        b.setFrameIndex(static_cast<std::uint32_t>(i));
        writePose(b.initPose(), local);
        b.setDescriptorType("u8");
      });
      w.append(0, stamp, *kf.storage());
    }
  }
  w.close();
  return path;
}

std::unique_ptr<ShardStitcherActor> stitcher(const std::vector<fs::path>& recordings) {
  ShardStitcherOptions o;
  for (const auto& r : recordings) o.recordings.push_back(r.string());
  return std::make_unique<ShardStitcherActor>(o);
}

double distance(const Pose3& a, const Pose3& b) {
  return (a.t - b.t).norm() + a.q.angularDistance(b.q);
}

}  // namespace shard_stitcher_test

using namespace shard_stitcher_test;

TEST_CASE("shard_stitcher publishes two shards as one sequence in shard 0's frame and clock",
          "[visual_slam][shard_stitcher]") {
  const auto dir = test::scratchDir("shard_stitcher");
  const auto a = writeShard(dir, "a.trec", {0, 24, {0, 8, 16, 22}});
  const auto b = writeShard(dir, "b.trec", {20, 40, {20, 30, 38}});
  ActorHarness h(stitcher({a, b}));
  for (int i = 0; i < 60; ++i) h.advance(kFrameNs);

  const Pose3 world_inv = trueCamera(0).inverse();
  const auto poses = h.published<msg::PoseStamped3D>("camera_pose");
  REQUIRE(poses.size() == 41);  // frames 20-24 once, from shard b
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const auto p = *poses[i];
    CHECK(p.getFrameIndex() == i);
    CHECK(p.getHeader().getStampNs() == static_cast<Nanos>(i) * kFrameNs);
    CHECK(distance(toPose3(p.getPose()), world_inv * trueCamera(static_cast<int>(i))) < 1e-9);
  }
  const auto keyframes = h.published<msg::Keyframe>("keyframes");
  const std::vector<std::uint32_t> frames = {0, 8, 16, 20, 30, 38};  // shard a's 22 dropped
  REQUIRE(keyframes.size() == frames.size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const auto k = *keyframes[i];
    CHECK(k.getId() == i);
    CHECK(k.getFrameIndex() == frames[i]);
    CHECK(std::string(k.getDescriptorType().cStr()) == "u8");
    CHECK(k.getHeader().getStampNs() == frames[i] * kFrameNs);
    CHECK(distance(toPose3(k.getPose()), world_inv * trueCamera(static_cast<int>(frames[i]))) <
          1e-9);
  }
  const auto truth = h.published<msg::GroundTruthPose3D>("ground_truth");
  REQUIRE(truth.size() == 41);
  for (std::size_t i = 0; i < truth.size(); ++i)
    CHECK(truth[i]->getHeader().getStampNs() == static_cast<Nanos>(i) * kFrameNs);

  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s["keyframes"]) == 6);
  CHECK(std::get<std::string>(s["join_frames"]) == "20");
  CHECK(std::get<std::int64_t>(s["dropped_overlap"]) == 5 + 5 + 1);
}

TEST_CASE("shard_stitcher refuses missing, damaged, mistyped, empty and non-finite recordings",
          "[visual_slam][shard_stitcher]") {
  using Catch::Matchers::Contains;
  const auto dir = test::scratchDir("shard_stitcher_bad");
  const auto good = writeShard(dir, "good.trec", {0, 12, {0, 6}});

  CHECK_THROWS_WITH(stitcher({}), Contains("'recordings': is required"));
  CHECK_THROWS_WITH(stitcher({good, dir / "missing.trec"}), Contains("missing.trec"));

  // Truncated: the last block cut short, so messages are lost.
  const auto cut = writeShard(dir, "cut.trec", {10, 30, {10, 20}});
  fs::resize_file(cut, fs::file_size(cut) - 200);
  CHECK_THROWS_WITH(stitcher({good, cut}), Contains("cut.trec") && Contains("damaged"));

  // Not a recording at all, and an empty file.
  std::ofstream(dir / "text.trec") << "frame,x,y\n1,2,3\n";
  CHECK_THROWS_WITH(stitcher({good, dir / "text.trec"}), Contains("text.trec"));
  std::ofstream(dir / "empty.trec").flush();
  CHECK_THROWS_WITH(stitcher({good, dir / "empty.trec"}), Contains("empty.trec"));

  // A recording without the front end's topics, and one with a topic of the wrong type.
  {
    RecordingWriter w((dir / "other.trec").string(),
                      {{"scan", messageTypeOf<msg::LaserScan>().id, "LaserScan"}});
    w.close();
  }
  CHECK_THROWS_WITH(stitcher({good, dir / "other.trec"}),
                    Contains("other.trec") && Contains("no topic 'keyframes'"));
  {
    RecordingWriter w(
        (dir / "typed.trec").string(),
        {{"keyframes", messageTypeOf<msg::Keyframe>().id, "Keyframe"},
         {"camera_pose", messageTypeOf<msg::GroundTruthPose3D>().id, "GroundTruthPose3D"},
         {"ground_truth", messageTypeOf<msg::GroundTruthPose3D>().id, "GroundTruthPose3D"}});
    w.close();
  }
  CHECK_THROWS_WITH(stitcher({good, dir / "typed.trec"}),
                    Contains("typed.trec") && Contains("expected PoseStamped3D"));

  // A shard that tracked nothing (no poses), and one with a NaN pose.
  {
    RecordingWriter w(
        (dir / "none.trec").string(),
        {{"keyframes", messageTypeOf<msg::Keyframe>().id, "Keyframe"},
         {"camera_pose", messageTypeOf<msg::PoseStamped3D>().id, "PoseStamped3D"},
         {"ground_truth", messageTypeOf<msg::GroundTruthPose3D>().id, "GroundTruthPose3D"}});
    w.close();
  }
  CHECK_THROWS_WITH(stitcher({good, dir / "none.trec"}),
                    Contains("none.trec") && Contains("tracked no frame"));
  const auto nan = writeShard(dir, "nan.trec", {10, 20, {10}, 14});
  CHECK_THROWS_WITH(stitcher({good, nan}), Contains("frame 14 is not finite"));

  // No shared frame between the shards.
  const auto gap = writeShard(dir, "gap.trec", {15, 25, {15}});
  CHECK_THROWS_WITH(stitcher({good, gap}), Contains("shares no tracked frame"));
  fs::remove_all(dir);
}
