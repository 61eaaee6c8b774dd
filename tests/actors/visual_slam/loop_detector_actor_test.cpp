// The rgbd_loop_detector actor through the mock-mailbox harness: keyframe messages of a camera that
// walks along a synthetic wall and comes back (bootstrapped vocabulary) give loop constraints
// from the earlier keyframe to the revisiting one with the true relative pose; broken keyframe
// messages are counted and skipped; a bad vocabulary file is a configuration error.
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/visual_slam/keyframe_message.hpp>
#include <tessera/visual_slam/loop_detector_actor.hpp>

#include "../../shared_data.hpp"
#include "synthetic_wall.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <fstream>
#include <functional>
#include <limits>

using namespace tessera;
using namespace tessera::visual_slam;

namespace {

std::int64_t summaryInt(const Summary& s, const std::string& key) {
  const auto it = s.find(key);
  return it == s.end() ? -1 : std::get<std::int64_t>(it->second);
}

// The tracker-style keyframe of the wall seen from camera_to_world.
Keyframe wallKeyframe(const test::Wall& wall, std::size_t id, const Eigen::Isometry3d& pose) {
  const LoopView v = test::view(wall, pose, static_cast<std::uint32_t>(500 + id));
  Keyframe k;
  k.id = id;
  k.frame = id * 5;
  k.camera_to_world = pose;
  k.descriptors = v.descriptors;
  for (std::size_t i = 0; i < v.size(); ++i) {
    k.keypoints.emplace_back(
        cv::Point2f(static_cast<float>(v.pixels[i].x()), static_cast<float>(v.pixels[i].y())),
        31.f);
    k.points_camera.push_back(v.points[i]);
  }
  return k;
}

void pushKeyframe(ActorHarness& h, const Keyframe& k,
                  const std::function<void(msg::Keyframe::Builder)>& spoil = {}) {
  h.push<msg::Keyframe>("keyframes", [&](msg::Keyframe::Builder b) {
    setHeader(b.initHeader(), static_cast<std::int64_t>(k.id) * 100'000'000, "world", k.id);
    KeyframeContent c;
    c.keyframe = &k;
    c.camera = test::kCamera;
    writeKeyframe(b, c);
    if (spoil) spoil(b);
  });
  h.runUntilIdle();
}

}  // namespace

TEST_CASE("rgbd_loop_detector publishes verified loops of a revisit",
          "[visual_slam][actors][loops]") {
  LoopDetectorActorOptions o;
  o.detector.bootstrap_keyframes = 12;
  o.detector.bootstrap_k = 8;
  ActorHarness h(std::make_unique<LoopDetectorActor>(o));
  const test::Wall wall(3);
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < 28; ++i) {
    const double x = i < 22 ? 1.0 + 0.4 * i : 1.05 + 0.4 * (i - 22);
    poses.push_back(test::cameraAt(x));
    pushKeyframe(h, wallKeyframe(wall, static_cast<std::size_t>(i), poses.back()));
  }
  const auto loops = h.published<msg::KeyframeConstraint>("loop_constraints");
  REQUIRE(loops.size() >= 3);
  for (const auto& m : loops) {
    const auto from = m->getFromId(), to = m->getToId();
    INFO(from << " -> " << to);
    CHECK(from < to);
    CHECK(to >= 22);
    CHECK(m->getInliers() >= 25);
    CHECK(m->getHeader().getStampNs() == static_cast<std::int64_t>(to) * 100'000'000);
    const Pose3 rel = toPose3(m->getRelative());
    const Eigen::Isometry3d truth = poses[from].inverse() * poses[to];
    CHECK((rel.t - truth.translation()).norm() < 0.02);
    REQUIRE(m->getRelative().getCovariance().size() == 36);
    CHECK(m->getRelative().getCovariance()[0] > 0);
  }
  Summary s;
  h.actor().summarize(s);
  CHECK(summaryInt(s, "keyframes_received") == 28);
  CHECK(summaryInt(s, "keyframes_bad") == 0);
  CHECK(summaryInt(s, "queries") == 28);
  CHECK(summaryInt(s, "published") == static_cast<std::int64_t>(loops.size()));
  CHECK(summaryInt(s, "verified") == static_cast<std::int64_t>(loops.size()));
  CHECK(std::get<std::string>(s.at("vocabulary")) == "bootstrap");
}

TEST_CASE("rgbd_loop_detector counts and skips keyframes it cannot use",
          "[visual_slam][actors][loops]") {
  ActorHarness h(std::make_unique<LoopDetectorActor>(LoopDetectorActorOptions{}));
  const test::Wall wall(3);
  const Keyframe k = wallKeyframe(wall, 0, test::cameraAt(2));
  pushKeyframe(h, k, [](msg::Keyframe::Builder b) { b.initKeypoints(0); });
  pushKeyframe(h, k, [](msg::Keyframe::Builder b) {
    b.getKeypoints()[1].setU(std::numeric_limits<float>::quiet_NaN());
  });
  pushKeyframe(h, k, [](msg::Keyframe::Builder b) { b.setDescriptorType("f32"); });
  pushKeyframe(h, k, [](msg::Keyframe::Builder b) { b.setDescriptorRows(3); });
  pushKeyframe(h, k);  // a good one: held for the bootstrap
  pushKeyframe(h, k);  // the same id again: out of order
  Summary s;
  h.actor().summarize(s);
  CHECK(summaryInt(s, "keyframes_received") == 6);
  CHECK(summaryInt(s, "keyframes_bad") == 5);
  CHECK(summaryInt(s, "bad_id_out_of_order_was_taken_before") == 1);
  CHECK(summaryInt(s, "queries") == 0);
  CHECK(h.publishedCount("loop_constraints") == 0);
}

TEST_CASE("rgbd_loop_detector refuses bad options and vocabulary files",
          "[visual_slam][actors][loops]") {
  LoopDetectorActorOptions o;
  o.vocabulary.path = "/nonexistent/voc.yml.gz";
  CHECK_THROWS_AS(LoopDetectorActor(o), ConfigError);
  const auto dir = test::scratchDir("loop_detector_voc");
  std::ofstream(dir / "bad.yml") << "%YAML:1.0\nvocabulary:\n  k: 10\n";
  o.vocabulary.path = (dir / "bad.yml").string();
  CHECK_THROWS_AS(LoopDetectorActor(o), ConfigError);
  o = {};
  o.detector.verifier.min_inliers = 0;
  CHECK_THROWS_AS(LoopDetectorActor(o), ConfigError);
}
