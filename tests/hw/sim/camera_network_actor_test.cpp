#include <tessera/msg/camera.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/sim/camera_network_actor.hpp>

#include <yaml-cpp/yaml.h>

#include <catch2/catch.hpp>

#include "../../shared_data.hpp"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

using namespace tessera;
using tessera::sim::CameraNetworkActor;
using tessera::sim::CameraNetworkOptions;

namespace {

// One camera at (12, 0), untilted: footprint x in [9, 15), y in (-2.25, 2.25].
CameraNetworkOptions oneCamera() {
  CameraNetworkOptions o;
  o.camera_sites = {{12, 0}};
  return o;
}

// Ground truth along y = 0 at 0.5 m/s, 50 Hz, from x = 0 to 20 (40 s).
void drive(ActorHarness& h) {
  for (int k = 0; k <= 2000; ++k) {
    h.push<msg::GroundTruthPose>("ground_truth", [&](msg::GroundTruthPose::Builder b) {
      setHeader(b.initHeader(), std::int64_t{k} * 20'000'000, "map", k);
      writePose(b.initPose(), tessera::Pose2{0.01 * k, 0, 0});
    });
    h.runUntilIdle();
  }
}

std::string configErrorOf(const CameraNetworkOptions& o) {
  try {
    CameraNetworkActor a(o);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("CameraNetworkActor: frames at camera_hz, enter/detections/leave on a straight pass",
          "[sim][actor][camera]") {
  CameraNetworkOptions o = oneCamera();
  o.camera.miss_probability = 0.1;
  ActorHarness h(std::make_unique<CameraNetworkActor>(o));
  drive(h);

  const auto events = h.published<msg::CameraEvent>("camera_events");
  REQUIRE(events.size() == 2);
  CHECK(events[0]->getEntered());
  CHECK(events[0]->getHeader().getStampNs() == 18'000'000'000);  // x = 9.0
  CHECK_FALSE(events[1]->getEntered());
  CHECK(events[1]->getHeader().getStampNs() == 30'000'000'000);  // x = 15.0
  CHECK(std::string(events[0]->getHeader().getFrameId().cStr()) == "camera_0");

  const auto det = h.published<msg::MarkerDetection>("camera_detections");
  REQUIRE(det.size() == 120);  // 12 s in view at 10 Hz
  int missed = 0;
  for (const auto& d : det) {
    const std::int64_t t = d->getHeader().getStampNs();
    CHECK(t % 100'000'000 == 0);
    const double x = 0.5 * static_cast<double>(t) * 1e-9;
    CHECK(d->getPixelStd() == 1.0);
    if (!d->getDetected()) {
      ++missed;
      continue;
    }
    CHECK(d->getU() == Approx(320 + 320 * (x - 12) / 3).margin(6));
    CHECK(d->getV() == Approx(240).margin(6));
  }
  CHECK(missed > 0);
  CHECK(missed < 40);
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("frames")) == 401);
  CHECK(std::get<std::int64_t>(s.at("events")) == 2);
}

TEST_CASE("CameraNetworkActor: the world's cameras and the cameras file", "[sim][actor][camera]") {
  const auto dir = test::scratchDir("camera_network_actor");
  CameraNetworkOptions o;  // builtin:camera_floor
  o.cameras_file = "cameras.txt";
  {
    ActorHarness h(std::make_unique<CameraNetworkActor>(o), dir.string());
    h.push<msg::GroundTruthPose>("ground_truth", [&](msg::GroundTruthPose::Builder b) {
      setHeader(b.initHeader(), 0, "map", 0);
      writePose(b.initPose(), tessera::Pose2{7.5, 7.5, 0});  // under camera 0
    });
    h.runUntilIdle();
    CHECK(h.publishedCount("camera_events") == 1);
    CHECK(h.publishedCount("camera_detections") == 1);
  }
  std::ifstream in(dir / "cameras.txt");
  std::string line;
  int rows = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    double v;
    int fields = 0;
    while (s >> v) ++fields;
    CHECK(fields == 17);
    ++rows;
  }
  CHECK(rows == 7);
  std::filesystem::remove_all(dir);
}

TEST_CASE("CameraNetworkActor: bad options are ConfigErrors", "[sim][actor][camera]") {
  CameraNetworkOptions o = oneCamera();
  o.camera_hz = 0;
  CHECK(configErrorOf(o).find("camera_hz") != std::string::npos);
  o = oneCamera();
  o.camera.miss_probability = 2;
  CHECK(configErrorOf(o).find("option 'camera.miss_probability'") != std::string::npos);
  o = oneCamera();
  o.marker = {1};
  CHECK(configErrorOf(o).find("marker") != std::string::npos);
  o = oneCamera();
  o.camera.focal_px = -1;
  CHECK(configErrorOf(o).find("option 'camera.focal_px'") != std::string::npos);
  o = {};
  o.world = "builtin:office";  // no cameras
  CHECK(configErrorOf(o).find("camera_sites") != std::string::npos);
  CHECK(ActorRegistry::instance().find("camera_network") != nullptr);
  CHECK(ActorRegistry::instance().find("world_writer") != nullptr);
}

TEST_CASE("CameraNetworkActor: the camera group from YAML, old flat keys name the new ones",
          "[sim][actor][camera][options]") {
  const auto read = [](const char* yaml) {
    return loadOptions<CameraNetworkOptions>(Params(YAML::Load(yaml), "test"));
  };
  const CameraNetworkOptions o = read("{camera_hz: 5, camera: {focal_px: 400, width_px: 800}}");
  CHECK(o.camera_hz == 5);
  CHECK(o.camera.focal_px == 400);
  CHECK(o.camera.width_px == 800);
  CHECK(o.camera.height_px == 480);  // default kept inside the group
  CHECK_THROWS_WITH(read("{miss_prob: 0.1}"), Catch::Contains("camera.miss_probability"));
  CHECK_THROWS_WITH(read("{image_width: 800}"), Catch::Contains("camera.width_px"));
}
