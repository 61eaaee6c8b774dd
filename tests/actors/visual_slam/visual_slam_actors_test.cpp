// The visual SLAM actors through the mock-mailbox harness: rgbd_front_end on the TUM fr1/desk
// frames and on broken frames, keyframe_graph on hand-made keyframe and loop messages (and on
// broken ones).
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/players/rgbd_player.hpp>
#include <tessera/pose_graph/pose_graph_io.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/visual_slam/keyframe_graph_actor.hpp>
#include <tessera/visual_slam/keyframe_message.hpp>
#include <tessera/visual_slam/rgbd_front_end_actor.hpp>

#include <yaml-cpp/yaml.h>
#include <catch2/catch.hpp>

#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <numbers>

#include "../../shared_data.hpp"

using namespace tessera;
using namespace tessera::visual_slam;
namespace fs = std::filesystem;

namespace {

std::int64_t summaryInt(const Summary& s, const std::string& key) {
  const auto it = s.find(key);
  return it == s.end() ? -1 : std::get<std::int64_t>(it->second);
}

Summary summaryOf(ActorHarness& h) {
  Summary s;
  h.actor().summarize(s);
  return s;
}

// The player's frames of a dataset folder (every frame, in order).
std::vector<Message<msg::RgbdFrame>> playerFrames(const fs::path& dir) {
  players::RgbdPlayerOptions o;
  o.path = dir.string();
  ActorHarness h(std::make_unique<players::RgbdPlayerActor>(o));
  for (int i = 0; i < 100; ++i) h.advance(kNanosPerSecond / 10);
  return h.published<msg::RgbdFrame>("rgbd");
}

// A keyframe of n features at camera_to_world = a translation along z.
Keyframe syntheticKeyframe(std::size_t id, double z, int n = 40) {
  Keyframe k;
  k.id = id;
  k.frame = id * 10;
  k.camera_to_world.translation() = Eigen::Vector3d(0, 0, z);
  k.descriptors = cv::Mat(n, 32, CV_8U);
  for (int i = 0; i < n; ++i) {
    k.keypoints.emplace_back(cv::Point2f(10.f + i, 20.f + i), 31.f, 45.f, 100.f, i % 8);
    k.points_camera.emplace_back(0.01 * i, 0.02 * i, 1.0 + 0.01 * i);
    for (int b = 0; b < 32; ++b)
      k.descriptors.at<std::uint8_t>(i, b) = static_cast<std::uint8_t>(i + b);
  }
  return k;
}

void pushKeyframe(ActorHarness& h, const Keyframe& k, std::int64_t stamp_ns,
                  const std::function<void(msg::Keyframe::Builder)>& spoil = {}) {
  h.push<msg::Keyframe>("keyframes", [&](msg::Keyframe::Builder b) {
    setHeader(b.initHeader(), stamp_ns, "world", k.id);
    KeyframeContent c;
    c.keyframe = &k;
    c.camera = {525, 525, 319.5, 239.5, 640, 480};
    c.depth = cv::Mat(480, 640, CV_16UC1, cv::Scalar(1000));
    c.depth_step = 8;
    c.tracking_inliers = 100;
    writeKeyframe(b, c);
    if (spoil) spoil(b);
  });
  h.runUntilIdle();
}

void pushLoop(ActorHarness& h, std::uint32_t from, std::uint32_t to, double dz,
              int cov_values = 36) {
  h.push<msg::KeyframeConstraint>("loop_constraints", [&](msg::KeyframeConstraint::Builder b) {
    setHeader(b.initHeader(), 0, "world", 0);
    b.setFromId(from);
    b.setToId(to);
    auto r = b.initRelative();
    writePose(r, Pose3{Eigen::Vector3d(0, 0, dz), Eigen::Quaterniond::Identity()});
    auto c = r.initCovariance(static_cast<unsigned>(cov_values));
    for (int i = 0; i < cov_values; ++i) c.set(static_cast<unsigned>(i), i % 7 == 0 ? 1e-4 : 0.0);
  });
  h.runUntilIdle();
}

}  // namespace

TEST_CASE("rgbd_front_end tracks the TUM fr1/desk frames and publishes poses and keyframes",
          "[visual_slam][actors]") {
  TESSERA_SHARED_DATA(dir, "tum-rgbd-fr1-desk-9frames");
  const auto frames = playerFrames(dir);
  REQUIRE(frames.size() == 9);
  ActorHarness h(std::make_unique<RgbdFrontEndActor>(RgbdFrontEndOptions{}));
  // One at a time: the mailbox keeps only the latest frame.
  for (const auto& f : frames) {
    h.push("rgbd", f);
    h.runUntilIdle();
  }
  const auto poses = h.published<msg::PoseStamped3D>("camera_pose");
  const auto keyframes = h.published<msg::Keyframe>("keyframes");
  REQUIRE(poses.size() == 9);
  CHECK(poses[0]->getStatus() == msg::PoseStamped3D::TrackingStatus::INITIALISED);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    CHECK(poses[i]->getFrameIndex() == frames[i]->getFrameIndex());
    CHECK(std::string(poses[i]->getChildFrameId().cStr()) == "camera");
    if (i > 0) CHECK(poses[i]->getStatus() == msg::PoseStamped3D::TrackingStatus::TRACKING);
  }
  REQUIRE(keyframes.size() >= 1);
  for (const auto& k : keyframes) {
    CHECK(keyframeMessageError(*k) == "");
    CHECK(k->getDepthWidth() == 160);
    CHECK(k->getDepthHeight() == 120);
    CHECK(std::string(k->getDescriptorType().cStr()) == "u8");
  }
  CHECK(keyframes.front()->getId() == 0);
  const Summary s = summaryOf(h);
  CHECK(summaryInt(s, "frames") == 9);
  CHECK(summaryInt(s, "lost") == 0);
  CHECK(summaryInt(s, "skipped") == 0);
  CHECK(summaryInt(s, "keyframes") == static_cast<std::int64_t>(keyframes.size()));
  REQUIRE(s.count("ate_rmse_m"));
  CHECK(std::get<double>(s.at("ate_rmse_m")) < 0.02);
  CHECK(s.count("ms_per_frame_p95"));
  CHECK(s.count("ms_extraction_mean"));
}

TEST_CASE("rgbd_front_end forget_trimmed bounds a keyframe_poses list by its own keyframes",
          "[visual_slam][actors][lifelong]") {
  TESSERA_SHARED_DATA(dir, "tum-rgbd-fr1-desk-9frames");
  const auto frames = playerFrames(dir);
  RgbdFrontEndOptions o;
  o.forget_trimmed = true;
  ActorHarness h(std::make_unique<RgbdFrontEndActor>(o));
  for (const auto& f : frames) {
    h.push("rgbd", f);
    h.runUntilIdle();
  }
  // A list whose newest id (4e9) the front end never made: it must not walk every id below it,
  // and forgets nothing it does not hold.
  const auto start = std::chrono::steady_clock::now();
  h.push<msg::KeyframePoses>("keyframe_poses", [](msg::KeyframePoses::Builder b) {
    auto poses = b.initPoses(2);
    poses[0].setId(0);
    poses[1].setId(4000000000u);
  });
  h.runUntilIdle();
  CHECK(std::chrono::steady_clock::now() - start < std::chrono::seconds(2));
  CHECK(summaryInt(summaryOf(h), "keyframes_forgotten") == 0);  // all within the local map
}

TEST_CASE("rgbd_front_end options: registration and matching live in the tracker's options",
          "[visual_slam][actors]") {
  const auto load = [](const std::string& yaml) {
    return loadOptions<RgbdFrontEndOptions>(Params(YAML::Load(yaml), "test"));
  };
  CHECK(load("{}").tracker.register_depth);
  const auto o = load("tracker: {register_depth: false, match_algorithm: flann}\n");
  CHECK_FALSE(o.tracker.register_depth);
  CHECK(o.tracker.matcher.algorithm == MatchAlgorithm::kFlann);
  CHECK_THROWS_WITH(load("register_depth: false\n"), Catch::Contains("tracker.register_depth"));
  CHECK_THROWS_WITH(load("tracker: {match_algorithm: kdtree}\n"),
                    Catch::Contains("brute_force | flann"));
  CHECK_THROWS_AS(load("tracker: {local_ba_keyframes: -1}\n").tracker.validate(),
                  std::invalid_argument);
}

TEST_CASE("rgbd_front_end skips and counts frames it cannot read", "[visual_slam][actors]") {
  TESSERA_SHARED_DATA(dir, "tum-rgbd-fr1-desk-9frames");
  const auto frames = playerFrames(dir);
  REQUIRE(frames.size() >= 2);
  ActorHarness h(std::make_unique<RgbdFrontEndActor>(RgbdFrontEndOptions{}));
  // A copy of a real frame with one thing broken.
  const auto broken = [&](const std::function<void(msg::RgbdFrame::Builder)>& spoil) {
    h.push<msg::RgbdFrame>("rgbd", [&](msg::RgbdFrame::Builder b) {
      b.setHeader(frames[0]->getHeader());
      b.setColor(frames[0]->getColor());
      b.setDepth(frames[0]->getDepth());
      b.setIntrinsics(frames[0]->getIntrinsics());
      b.setDepthScale(frames[0]->getDepthScale());
      b.setColorRegistered(true);
      spoil(b);
    });
    h.runUntilIdle();
  };
  broken([](auto b) { b.getColor().setEncoding("yuv422"); });
  broken([](auto b) { b.getDepth().setEncoding("8UC1"); });
  broken([](auto b) { b.getColor().initData(100); });
  broken([](auto b) { b.getDepth().setHeight(0); });
  broken([](auto b) {
    auto d = b.getDepth();
    d.setWidth(320);
    d.setStep(640);
  });
  broken([](auto b) {  // no valid depth at all: the map cannot start
    auto d = b.getDepth().getData();
    std::fill(d.begin(), d.end(), 0);
  });
  broken([](auto b) { b.setDepthScale(std::numeric_limits<double>::quiet_NaN()); });
  CHECK(h.publishedCount("camera_pose") == 0);
  // A good frame afterwards still starts tracking.
  h.push("rgbd", frames[1]);
  h.runUntilIdle();
  CHECK(h.publishedCount("camera_pose") == 1);
  const Summary s = summaryOf(h);
  CHECK(summaryInt(s, "frames") == 8);
  CHECK(summaryInt(s, "skipped") == 7);
  CHECK(summaryInt(s, "skipped_color_encoding") == 1);
  CHECK(summaryInt(s, "skipped_depth_encoding") == 1);
  CHECK(summaryInt(s, "skipped_color_data_short") == 1);
  CHECK(summaryInt(s, "skipped_depth_empty") == 1);
  CHECK(summaryInt(s, "skipped_depth_size") == 1);

  // Intrinsics that cannot be used: every frame skipped, never a throw.
  ActorHarness h2(std::make_unique<RgbdFrontEndActor>(RgbdFrontEndOptions{}));
  h2.push<msg::RgbdFrame>("rgbd", [&](msg::RgbdFrame::Builder b) {
    b.setColor(frames[0]->getColor());
    b.setDepth(frames[0]->getDepth());
    b.initIntrinsics().setFx(std::numeric_limits<double>::quiet_NaN());
  });
  h2.runUntilIdle();
  CHECK(summaryInt(summaryOf(h2), "skipped_bad_intrinsics") == 1);

  RgbdFrontEndOptions bad;
  bad.tracker.min_tracking_inliers = -1;
  CHECK_THROWS_WITH(RgbdFrontEndActor(bad), Catch::Contains("min_tracking_inliers"));
}

TEST_CASE("keyframe_graph closes a loop, republishes poses and writes its files",
          "[visual_slam][actors]") {
  const fs::path out = tessera::test::scratchDir("keyframe_graph_actor");
  KeyframeGraphActorOptions o;
  o.graph.odometry_sigma_translation = 0.05;  // as large as the drift below
  ActorHarness h(std::make_unique<KeyframeGraphActor>(o), out.string());
  // Keyframes along z that drifted: 0, 0.55, 1.1, 1.65 where the truth is 0, 0.5, 1.0, 1.5.
  for (std::size_t i = 0; i < 4; ++i)
    pushKeyframe(h, syntheticKeyframe(i, 0.55 * static_cast<double>(i)),
                 static_cast<std::int64_t>(i) * kNanosPerSecond);
  CHECK(h.publishedCount("keyframe_poses") == 0);  // odometry alone: nothing to optimise
  pushLoop(h, 3, 0, -1.5);                         // keyframe 0 seen 1.5 m behind keyframe 3
  const auto poses = h.published<msg::KeyframePoses>("keyframe_poses");
  REQUIRE(poses.size() == 1);
  REQUIRE(poses[0]->getPoses().size() == 4);
  const double z3 = poses[0]->getPoses()[3].getPose().getZ();
  CHECK(std::abs(z3 - 1.5) < 0.01);
  h.stop();
  CHECK(h.publishedCount("keyframe_poses") == 2);
  const auto tum = mapping::readTum(out / "keyframes.tum");
  REQUIRE(tum.size() == 4);
  CHECK(tum[2].stamp_ns == 2 * kNanosPerSecond);
  const auto g2o = pose_graph::readPoseGraph(out / "keyframe_graph.g2o");
  CHECK(g2o.dimension == 3);
  CHECK(g2o.graph3d.size() == 4);
  CHECK(g2o.graph3d.edges.size() == 4);
  CHECK(g2o.graph3d.fixed[0]);
  const Summary s = summaryOf(h);
  CHECK(summaryInt(s, "loops_added") == 1);
  CHECK(summaryInt(s, "keyframes_bad") == 0);
  CHECK(summaryInt(s, "optimizations") == 1);
}

TEST_CASE("keyframe_graph moves every frame's pose with its keyframe's optimisation",
          "[visual_slam][actors]") {
  const fs::path out = tessera::test::scratchDir("keyframe_graph_frames");
  KeyframeGraphActorOptions o;
  o.graph.odometry_sigma_translation = 0.05;
  o.frames_file = "trajectory_optimized.tum";
  ActorHarness h(std::make_unique<KeyframeGraphActor>(o), out.string());
  auto pushFrame = [&](std::int64_t stamp, double z, bool nan = false) {
    h.push<msg::PoseStamped3D>("camera_pose", [&](msg::PoseStamped3D::Builder b) {
      setHeader(b.initHeader(), stamp, "world", 0);
      writePose(b.initPose(), Pose3{Eigen::Vector3d(0.1, nan ? std::nan("") : 0.0, z),
                                    Eigen::Quaterniond::Identity()});
    });
    h.runUntilIdle();
  };
  // Keyframes every second along z with 10 % drift, frames every half second between them.
  for (std::size_t i = 0; i < 4; ++i) {
    const auto t = static_cast<std::int64_t>(i) * kNanosPerSecond;
    pushFrame(t, 0.55 * static_cast<double>(i));
    pushKeyframe(h, syntheticKeyframe(i, 0.55 * static_cast<double>(i)), t);
    pushFrame(t + kNanosPerSecond / 2, 0.55 * static_cast<double>(i) + 0.2);
  }
  pushFrame(5 * kNanosPerSecond, 0.0, true);  // a NaN pose: counted, not written
  pushLoop(h, 3, 0, -1.5);
  h.stop();
  const auto frames = mapping::readTum(out / "trajectory_optimized.tum");
  REQUIRE(frames.size() == 8);
  // Keyframe 3 moved from 1.65 to 1.5 m: its frame and the one after it move with it, and the
  // frame half a second later keeps its 0.2 m offset from the keyframe.
  CHECK(frames[6].position.z() == Approx(1.5).margin(0.01));
  CHECK(frames[7].position.z() == Approx(1.7).margin(0.01));
  CHECK(frames[7].position.x() == Approx(0.1).margin(1e-9));
  CHECK(frames[0].position.z() == Approx(0.0).margin(1e-9));  // the fixed first keyframe
  const Summary s = summaryOf(h);
  CHECK(summaryInt(s, "frames_received") == 9);
  CHECK(summaryInt(s, "frames_bad") == 1);
}

TEST_CASE("keyframe_graph in lifelong mode trims a covered keyframe and leaves it out",
          "[visual_slam][actors][lifelong]") {
  // Out along z with 10 % drift (0, 0.55, ... 2.75), then back where keyframe 1 stood; a frame
  // just after keyframe 1; a loop from keyframe 0 to 6.
  const auto drive = [](bool trimming, const fs::path& out) {
    KeyframeGraphActorOptions o;
    o.graph.odometry_sigma_translation = 0.05;
    o.graph.trimming.enabled = trimming;
    o.graph.trimming.min_age = 3;
    o.frames_file = "trajectory_optimized.tum";
    auto h = std::make_unique<ActorHarness>(std::make_unique<KeyframeGraphActor>(o), out.string());
    for (std::size_t i = 0; i < 6; ++i) {
      const auto t = static_cast<std::int64_t>(i) * kNanosPerSecond;
      pushKeyframe(*h, syntheticKeyframe(i, 0.55 * static_cast<double>(i)), t);
    }
    pushKeyframe(*h, syntheticKeyframe(6, 0.6), 6 * kNanosPerSecond);
    h->push<msg::PoseStamped3D>("camera_pose", [&](msg::PoseStamped3D::Builder b) {
      setHeader(b.initHeader(), kNanosPerSecond + 1, "world", 0);
      writePose(b.initPose(), Pose3{Eigen::Vector3d(0, 0, 0.56), Eigen::Quaterniond::Identity()});
    });
    h->runUntilIdle();
    // Keyframe 6 seen 0.5 m ahead of keyframe 0: back where keyframe 1 stood. The loop's cycle
    // runs through keyframe 1, so it moves; then keyframe 6 covers it.
    pushLoop(*h, 0, 6, 0.5);
    return h;
  };
  const fs::path out = tessera::test::scratchDir("keyframe_graph_trim");
  auto h = drive(true, out);
  const auto poses = h->published<msg::KeyframePoses>("keyframe_poses");
  REQUIRE(poses.size() == 1);
  std::vector<std::uint32_t> ids;
  for (const auto p : poses[0]->getPoses()) ids.push_back(p.getId());
  CHECK(ids == std::vector<std::uint32_t>{0, 2, 3, 4, 5, 6});
  // The detector had not heard yet: a loop to the trimmed keyframe is refused and counted.
  pushLoop(*h, 1, 5, -1.0);
  h->stop();
  const Summary s = summaryOf(*h);
  CHECK(summaryInt(s, "keyframes_trimmed") == 1);
  CHECK(summaryInt(s, "graph_keyframes") == 6);
  CHECK(summaryInt(s, "constraints_bad") == 1);
  CHECK(summaryInt(s, "constraints_unresolved") == 0);
  CHECK(mapping::readTum(out / "keyframes.tum").size() == 6);
  CHECK(pose_graph::readPoseGraph(out / "keyframe_graph.g2o").graph3d.size() == 6);
  // The frame after keyframe 1 kept keyframe 1's correction from when it was trimmed: where the
  // same run without trimming (and without the refused loop) puts it.
  const fs::path kept_out = tessera::test::scratchDir("keyframe_graph_no_trim");
  auto kept = drive(false, kept_out);
  kept->stop();
  const auto frames = mapping::readTum(out / "trajectory_optimized.tum");
  const auto expected = mapping::readTum(kept_out / "trajectory_optimized.tum");
  REQUIRE(frames.size() == 1);
  REQUIRE(expected.size() == 1);
  INFO("frame z " << frames[0].position.z() << " m, without trimming " << expected[0].position.z()
                  << " m");
  CHECK((frames[0].position - expected[0].position).norm() < 1e-9);
  CHECK(std::abs(frames[0].position.z() - 0.56) > 0.005);  // the correction did move it
}

TEST_CASE("keyframe_graph counts and skips bad keyframe and constraint messages",
          "[visual_slam][actors]") {
  ActorHarness h(std::make_unique<KeyframeGraphActor>(KeyframeGraphActorOptions{}));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  pushKeyframe(h, syntheticKeyframe(0, 0), 0);
  // Empty descriptors.
  pushKeyframe(h, syntheticKeyframe(1, 0.5), 1, [](auto b) {
    b.initDescriptors(0);
    b.setDescriptorRows(0);
  });
  // No keypoints at all.
  pushKeyframe(h, syntheticKeyframe(2, 0.5, 0), 2);
  // Counts that disagree.
  pushKeyframe(h, syntheticKeyframe(3, 0.5), 3, [](auto b) { b.initPoints(5); });
  pushKeyframe(h, syntheticKeyframe(4, 0.5), 4, [](auto b) { b.setDescriptorRows(39); });
  pushKeyframe(h, syntheticKeyframe(5, 0.5), 5, [](auto b) { b.setDescriptorType("u16"); });
  pushKeyframe(h, syntheticKeyframe(6, 0.5), 6, [](auto b) { b.setDepthWidth(7); });
  // NaN pose, zero quaternion, NaN point.
  pushKeyframe(h, syntheticKeyframe(7, 0.5), 7, [&](auto b) { b.getPose().setX(nan); });
  pushKeyframe(h, syntheticKeyframe(8, 0.5), 8, [](auto b) {
    auto p = b.getPose();
    p.setQw(0);
    p.setQx(0);
    p.setQy(0);
    p.setQz(0);
  });
  pushKeyframe(h, syntheticKeyframe(9, 0.5), 9,
               [&](auto b) { b.getPoints()[3].setZ(static_cast<float>(nan)); });
  // A repeated id.
  pushKeyframe(h, syntheticKeyframe(0, 0.5), 10);
  pushKeyframe(h, syntheticKeyframe(11, 0.5), 11);
  // Constraints: too few covariance values, a self-loop, a NaN pose.
  pushLoop(h, 11, 0, -0.5, 35);
  pushLoop(h, 11, 11, 0);
  pushLoop(h, 11, 0, nan);
  pushLoop(h, 42, 0, -0.5);  // waits for keyframe 42, which never comes
  h.stop();
  const Summary s = summaryOf(h);
  CHECK(summaryInt(s, "keyframes_received") == 12);
  CHECK(summaryInt(s, "keyframes_bad") == 10);
  CHECK(summaryInt(s, "graph_keyframes") == 2);
  CHECK(summaryInt(s, "constraints_received") == 4);
  CHECK(summaryInt(s, "constraints_bad") == 3);
  CHECK(summaryInt(s, "constraints_unresolved") == 1);
  CHECK(summaryInt(s, "loops_added") == 0);
  const auto poses = h.published<msg::KeyframePoses>("keyframe_poses");
  REQUIRE(poses.size() == 1);  // at stop
  for (const auto p : poses.back()->getPoses()) CHECK(std::isfinite(p.getPose().getZ()));
}

TEST_CASE("keyframe messages carry SIFT (float) descriptors and depth samples intact",
          "[visual_slam][actors]") {
  Keyframe k = syntheticKeyframe(3, 1.0, 5);
  k.descriptors = cv::Mat(5, 128, CV_32F);
  for (int i = 0; i < 5; ++i)
    for (int b = 0; b < 128; ++b) k.descriptors.at<float>(i, b) = 0.5f * static_cast<float>(i * b);
  cv::Mat depth(480, 640, CV_16UC1, cv::Scalar(0));
  depth.at<std::uint16_t>(8, 16) = 1234;  // sample (2, 1) at step 8
  Loan<msg::Keyframe> loan;
  KeyframeContent c;
  c.keyframe = &k;
  c.camera = {525, 525, 319.5, 239.5, 640, 480};
  c.depth = depth;
  c.depth_step = 8;
  writeKeyframe(*loan, c);
  const Message<msg::Keyframe> m(std::move(loan).seal());
  CHECK(keyframeMessageError(*m) == "");
  CHECK(std::string(m->getDescriptorType().cStr()) == "f32");
  CHECK(m->getDescriptorBytes() == 512);
  float value = 0;
  std::memcpy(&value, m->getDescriptors().begin() + 4 * 512 + 4 * 100, 4);
  CHECK(value == 200.0f);
  REQUIRE(m->getDepthWidth() == 80);
  REQUIRE(m->getDepthHeight() == 60);
  const auto d = m->getDepth();
  const std::size_t at = 2 * (1 * 80 + 2);
  CHECK((d[at] | (d[at + 1] << 8)) == 1234);
  CHECK(m->getPoints()[4].getValid());
  CHECK(std::abs(m->getPoints()[4].getZ() - 1.04f) < 1e-6);
}
