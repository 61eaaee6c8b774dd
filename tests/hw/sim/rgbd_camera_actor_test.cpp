// The rgbd_camera actor through the harness: frame rate from ground-truth poses, the RgbdFrame
// fields (encodings, depth in mm or metres, intrinsics, ground truth), and option errors naming
// the full key.
#include <tessera/msg/image.capnp.h>
#include <tessera/messages/geometry.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/sim/rgbd_camera_actor.hpp>

#include <yaml-cpp/yaml.h>

#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <string>

using namespace tessera;
using tessera::sim::RgbdCameraActor;
using tessera::sim::RgbdCameraOptions;

namespace {

// A small noise-free camera 1.6 m up looking along +x, whose centre pixel (80, 60) looks
// exactly along the optical axis, in the built-in 10 m x 8 m room.
RgbdCameraOptions small() {
  RgbdCameraOptions o;
  o.world = "builtin:room";
  o.rate_hz = 10;
  o.camera.width = 160;
  o.camera.height = 120;
  o.camera.fx = o.camera.fy = 130;
  o.camera.cx = 80;
  o.camera.cy = 60;
  o.camera.depth_noise = 0;
  o.camera.image_noise = 0;
  o.camera.mount = {0, 0, 1.6, 0, 0, 0};
  return o;
}

// Ground truth at (2, 3, 0) at 50 Hz for one second.
void drive(ActorHarness& h) {
  for (int k = 0; k <= 50; ++k) {
    h.push<msg::GroundTruthPose>("ground_truth", [&](msg::GroundTruthPose::Builder b) {
      setHeader(b.initHeader(), std::int64_t{k} * 20'000'000, "map", k);
      writePose(b.initPose(), tessera::Pose2{2, 3, 0});
    });
    h.runUntilIdle();
  }
}

std::string errorOf(const std::string& yaml) {
  try {
    RgbdCameraActor a(loadOptions<RgbdCameraOptions>(Params(YAML::Load(yaml), "test")));
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("RgbdCameraActor: frames at rate_hz with registered colour, depth and ground truth",
          "[sim][actor][rgbd]") {
  RgbdCameraOptions o = small();
  for (const char* depth : {"uint16", "float"}) {
    o.depth = depth;
    ActorHarness h(std::make_unique<RgbdCameraActor>(o));
    drive(h);
    const auto frames = h.published<msg::RgbdFrame>("rgbd");
    const auto gt = h.published<msg::GroundTruthPose3D>("ground_truth_3d");
    REQUIRE(frames.size() == 11);  // 0, 0.1, ..., 1.0 s
    REQUIRE(gt.size() == 11);
    const auto f = frames[3];
    CHECK(f->getHeader().getStampNs() == 300'000'000);
    CHECK(std::string(f->getColor().getEncoding().cStr()) == "rgb8");
    CHECK(f->getColor().getData().size() == 160u * 120u * 3u);
    CHECK(f->getColorRegistered());
    CHECK(f->getHasGroundTruth());
    CHECK(f->getIntrinsics().getFx() == 130);
    CHECK(f->getIntrinsics().getWidth() == 160);
    const Pose3 truth = toPose3(gt[3]->getPose());
    CHECK(truth.t.isApprox(Eigen::Vector3d(2, 3, 1.6)));
    CHECK(toPose3(f->getGroundTruth()).t.isApprox(truth.t));
    // Optical z (forward) along world +x.
    CHECK((truth.q * Eigen::Vector3d::UnitZ()).isApprox(Eigen::Vector3d::UnitX(), 1e-9));
    CHECK(std::string(gt[3]->getChildFrameId().cStr()) == "camera");

    const auto data = f->getDepth().getData();
    const std::size_t centre = 60 * 160 + 80;
    if (o.depth == "uint16") {
      CHECK(std::string(f->getDepth().getEncoding().cStr()) == "16UC1");
      CHECK(f->getDepthScale() == 1000);
      std::uint16_t mm = 0;
      std::memcpy(&mm, data.begin() + centre * 2, 2);
      CHECK(mm > 0);
    } else {
      CHECK(std::string(f->getDepth().getEncoding().cStr()) == "32FC1");
      CHECK(f->getDepthScale() == 1);
      float z = 0;
      std::memcpy(&z, data.begin() + centre * 4, 4);
      CHECK(z > 0);
    }
    Summary s;
    h.actor().summarize(s);
    CHECK(std::get<std::int64_t>(s["frames_published"]) == 11);
  }
}

TEST_CASE("RgbdCameraActor: depth of the centre pixel is the distance to the wall ahead",
          "[sim][actor][rgbd]") {
  const RgbdCameraOptions o = small();
  const RgbdCameraActor a(o);
  const Eigen::Isometry3d pose = a.renderer().cameraPose({2, 3, 0});
  const double expected = a.renderer().castRay(pose.translation(), {1, 0, 0});
  ActorHarness h(std::make_unique<RgbdCameraActor>(o));
  drive(h);
  const auto frames = h.published<msg::RgbdFrame>("rgbd");
  REQUIRE_FALSE(frames.empty());
  std::uint16_t mm = 0;
  std::memcpy(&mm, frames[0]->getDepth().getData().begin() + (60 * 160 + 80) * 2, 2);
  CHECK(mm == static_cast<std::uint16_t>(std::lround(expected * 1000)));
}

TEST_CASE("RgbdCameraActor: bad options are ConfigErrors naming the key", "[sim][actor][rgbd]") {
  CHECK_THAT(errorOf("{camera: {width: 0}}"), Catch::Contains("camera.width"));
  CHECK_THAT(errorOf("{camera: {height: 0}}"), Catch::Contains("camera.height"));
  CHECK_THAT(errorOf("{camera: {mount: {x: .nan}}}"), Catch::Contains("camera.mount.x"));
  CHECK_THAT(errorOf("{camera: {mount: {pitch: .inf}}}"), Catch::Contains("camera.mount.pitch"));
  CHECK_THAT(errorOf("{camera: {mount: {z: 3.0}}}"), Catch::Contains("camera.mount.z"));
  CHECK_THAT(errorOf("{camera: {depth_noise: -0.1}}"), Catch::Contains("camera.depth_noise"));
  CHECK_THAT(errorOf("{camera: {image_noise: -1}}"), Catch::Contains("camera.image_noise"));
  CHECK_THAT(errorOf("{camera: {range_max: 0.1}}"), Catch::Contains("camera.range_max"));
  CHECK_THAT(errorOf("{wall_height: 0}"), Catch::Contains("wall_height"));
  CHECK_THAT(errorOf("{wall_height: .nan}"), Catch::Contains("wall_height"));
  CHECK_THAT(errorOf("{rate_hz: 0}"), Catch::Contains("rate_hz"));
  CHECK_THAT(errorOf("{depth: mm}"), Catch::Contains("depth"));
  CHECK_THAT(errorOf("{world: builtin:nowhere}"), Catch::Contains("world"));
  CHECK_THAT(errorOf("{frame_id: ''}"), Catch::Contains("frame_id"));

  const auto* entry = ActorRegistry::instance().find("rgbd_camera");
  REQUIRE(entry != nullptr);
  for (const auto& row : entry->options()) CHECK_FALSE(row[2].empty());  // every key documented
}
