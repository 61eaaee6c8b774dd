#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/image.capnp.h>
#include <tessera/camera_network/marker_detector.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/sim/camera_image.hpp>
#include <tessera/sim/camera_network_actor.hpp>

#include <yaml-cpp/yaml.h>

#include <catch2/catch.hpp>
#include <opencv2/core.hpp>

#include "../../shared_data.hpp"
#include "polygon_margin.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

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

namespace camera_footprints_test {

// x0, y0, x1, y1, ... as points.
std::vector<Eigen::Vector2d> polygonOf(msg::CameraFootprints::Footprint::Reader f) {
  const auto xy = f.getXy();
  REQUIRE(xy.size() % 2 == 0);
  std::vector<Eigen::Vector2d> out;
  for (unsigned i = 0; i + 1 < xy.size(); i += 2) out.emplace_back(xy[i], xy[i + 1]);
  return out;
}

using tessera::test::insideMargin;

void pushPose(ActorHarness& h, std::int64_t stamp, double x, double y) {
  h.push<msg::GroundTruthPose>("ground_truth", [&](msg::GroundTruthPose::Builder b) {
    setHeader(b.initHeader(), stamp, "map", 0);
    writePose(b.initPose(), tessera::Pose2{x, y, 0});
  });
  h.runUntilIdle();
}

}  // namespace camera_footprints_test

TEST_CASE("CameraNetworkActor: camera_footprints at the first frame and every footprint_period_s",
          "[sim][actor][camera][footprint]") {
  using camera_footprints_test::insideMargin;
  using camera_footprints_test::polygonOf;
  using camera_footprints_test::pushPose;
  CameraNetworkOptions o;  // builtin:camera_floor: 7 cameras, yawed and tilted; 5 s
  ActorHarness h(std::make_unique<CameraNetworkActor>(o));
  const auto& network = static_cast<CameraNetworkActor&>(h.actor()).network();
  h.advance(2 * kNanosPerSecond);  // no frame yet: nothing
  CHECK(h.publishedCount("camera_footprints") == 0);
  pushPose(h, 0, 7.5, 7.5);
  REQUIRE(h.publishedCount("camera_footprints") == 1);

  const auto m = h.published<msg::CameraFootprints>("camera_footprints")[0];
  CHECK(std::string(m->getHeader().getFrameId().cStr()) == "map");
  REQUIRE(m->getCameras().size() == network.cameras().size());
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> offset(-6, 6);
  for (unsigned i = 0; i < m->getCameras().size(); ++i) {
    const auto f = m->getCameras()[i];
    const auto& cam = network.cameras()[i];
    CAPTURE(cam.id());
    CHECK(f.getCameraId() == cam.id());
    CHECK_FALSE(f.getCalibrated());
    const auto poly = polygonOf(f);
    REQUIRE(poly.size() >= 3);
    CHECK(insideMargin(poly, cam.site().position) > 0.5);  // counter-clockwise, holds the site
    int in = 0, out = 0;
    for (int k = 0; k < 400; ++k) {
      const Eigen::Vector2d p = cam.site().position + Eigen::Vector2d(offset(rng), offset(rng));
      const double margin = insideMargin(poly, p);
      if (std::abs(margin) < 1e-6) continue;
      CAPTURE(p.x(), p.y());
      CHECK(cam.inView(p) == (margin > 0));
      ++(margin > 0 ? in : out);
    }
    CHECK(in > 10);
    CHECK(out > 10);
  }

  // Again after footprint_period_s (run clock), and again after the next.
  h.advance(4 * kNanosPerSecond);  // t = 6 s: the timer fired at 5 s
  CHECK(h.publishedCount("camera_footprints") == 2);
  h.advance(3 * kNanosPerSecond);  // 9 s
  CHECK(h.publishedCount("camera_footprints") == 2);
  h.advance(2 * kNanosPerSecond);  // 11 s
  CHECK(h.publishedCount("camera_footprints") == 3);
  pushPose(h, 100'000'000, 7.5, 7.5);  // later frames do not add any
  CHECK(h.publishedCount("camera_footprints") == 3);
  const auto all = h.published<msg::CameraFootprints>("camera_footprints");
  CHECK(all[2]->getCameras().size() == network.cameras().size());
  CHECK(all[2]->getHeader().getSeq() == 2);
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("footprint_messages")) == 3);
}

TEST_CASE("CameraNetworkActor: footprint_period_s = 0 publishes the footprints once",
          "[sim][actor][camera][footprint]") {
  CameraNetworkOptions o = oneCamera();
  o.footprint_period_s = 0;
  ActorHarness h(std::make_unique<CameraNetworkActor>(o));
  camera_footprints_test::pushPose(h, 0, 0, 0);
  h.advance(30 * kNanosPerSecond);
  REQUIRE(h.publishedCount("camera_footprints") == 1);
  // One camera at (12, 0), untilted: x in [9, 15], y in [-2.25, 2.25].
  const auto poly = camera_footprints_test::polygonOf(
      h.published<msg::CameraFootprints>("camera_footprints")[0]->getCameras()[0]);
  REQUIRE(poly.size() == 4);
  for (const auto& p : poly) {
    CHECK(std::abs(std::abs(p.x() - 12) - 3) < 1e-9);
    CHECK(std::abs(std::abs(p.y()) - 2.25) < 1e-9);
  }
  CHECK(camera_footprints_test::insideMargin(poly, {12, 0}) == Approx(2.25));

  o.footprint_period_s = -1;
  CHECK(configErrorOf(o).find("footprint_period_s") != std::string::npos);
  o.footprint_period_s = std::numeric_limits<double>::quiet_NaN();
  CHECK(configErrorOf(o).find("footprint_period_s") != std::string::npos);
}

namespace camera_images_test {

/// The pixels of an image message (mono8) as a Mat over its bytes.
cv::Mat pixelsOf(const Message<msg::Image>& m) {
  return cv::Mat(static_cast<int>(m->getHeight()), static_cast<int>(m->getWidth()), CV_8UC1,
                 const_cast<std::uint8_t*>(m->getData().begin()), m->getStep());
}

std::int64_t figure(ActorHarness& h, const char* key) {
  Summary s;
  h.actor().summarize(s);
  return std::get<std::int64_t>(s.at(key));
}

}  // namespace camera_images_test

TEST_CASE("CameraNetworkActor: render_images publishes each camera's image near its view",
          "[sim][actor][camera][camera_images]") {
  using camera_images_test::figure;
  using camera_images_test::pixelsOf;
  CameraNetworkOptions o = oneCamera();  // footprint x in [9, 15): images for x in [8, 16]
  o.render_images = true;
  ActorHarness h(std::make_unique<CameraNetworkActor>(o));
  drive(h);  // x = 0.5 t

  const auto images = h.published<msg::Image>("camera_images");
  REQUIRE(images.size() >= 159);  // t = 16 .. 32 s at 10 Hz (the ends are on the margin)
  REQUIRE(images.size() <= 161);
  CHECK(figure(h, "images") == static_cast<std::int64_t>(images.size()));
  const auto cam = static_cast<CameraNetworkActor&>(h.actor()).network().cameras()[0];
  const tessera::camera_network::MarkerDetector detector;
  int in_view = 0, found = 0;
  for (const auto& m : images) {
    const std::int64_t t = m->getHeader().getStampNs();
    const double x = 0.5 * static_cast<double>(t) * 1e-9;
    CAPTURE(x);
    CHECK(t % 100'000'000 == 0);
    CHECK(x >= 8.0 - 1e-9);
    CHECK(x <= 16.0 + 1e-9);
    CHECK(std::string(m->getHeader().getFrameId().cStr()) == "camera_0");
    CHECK(std::string(m->getEncoding().cStr()) == "mono8");
    REQUIRE(m->getWidth() == 640);
    REQUIRE(m->getHeight() == 480);
    REQUIRE(m->getStep() == 640);
    REQUIRE(m->getData().size() == 640u * 480u);
    const auto markers = detector.detect(pixelsOf(m));
    if (x > 9.5 && x < 14.5) {  // the whole marker well inside the image
      ++in_view;
      REQUIRE(markers.size() == 1);
      CHECK(markers[0].id == 7);
      const Eigen::Vector2d truth = *cam.project({x, 0.0});
      CHECK((markers[0].centre - truth).norm() < 1.0);
      ++found;
    } else if (x < 8.8 || x > 15.2) {  // the marker and its quiet zone outside: only floor
      CHECK(markers.empty());
    }
  }
  CHECK(in_view > 90);
  CHECK(found == in_view);
  // The geometric detections are still published, and the images do not change them.
  CHECK(h.publishedCount("camera_events") == 2);
  CHECK(h.publishedCount("camera_detections") == 120);
  ActorHarness plain(std::make_unique<CameraNetworkActor>(oneCamera()));
  drive(plain);
  const auto a = h.published<msg::MarkerDetection>("camera_detections");
  const auto b = plain.published<msg::MarkerDetection>("camera_detections");
  REQUIRE(a.size() == b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a[i]->getDetected() == b[i]->getDetected());
    CHECK(a[i]->getU() == b[i]->getU());
    CHECK(a[i]->getV() == b[i]->getV());
  }
  CHECK(plain.publishedCount("camera_images") == 0);
}

TEST_CASE("CameraNetworkActor: publish_detections = false leaves only images and footprints",
          "[sim][actor][camera][camera_images]") {
  CameraNetworkOptions o;  // builtin:camera_floor: 7 cameras
  o.render_images = true;
  o.publish_detections = false;
  ActorHarness h(std::make_unique<CameraNetworkActor>(o));
  const auto& network = static_cast<CameraNetworkActor&>(h.actor()).network();
  // Under camera 0, then far from every camera.
  const Eigen::Vector2d under0 = network.cameras()[0].site().position;
  camera_footprints_test::pushPose(h, 0, under0.x(), under0.y());
  camera_footprints_test::pushPose(h, 100'000'000, -100, -100);
  CHECK(h.publishedCount("camera_events") == 0);
  CHECK(h.publishedCount("camera_detections") == 0);
  CHECK(h.publishedCount("camera_footprints") == 1);
  const auto images = h.published<msg::Image>("camera_images");
  REQUIRE(!images.empty());  // camera 0, and any neighbour whose margin holds the site
  CHECK(std::string(images[0]->getHeader().getFrameId().cStr()) == "camera_0");
  for (const auto& m : images) CHECK(m->getHeader().getStampNs() == 0);
  const auto markers =
      tessera::camera_network::MarkerDetector().detect(camera_images_test::pixelsOf(images[0]));
  REQUIRE(markers.size() == 1);
  CHECK(markers[0].id == 7);
  CHECK((markers[0].centre - *network.cameras()[0].project(under0)).norm() < 1.0);
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("frames")) == 2);
  CHECK(std::get<std::int64_t>(s.at("detections")) == 0);
  CHECK(std::get<std::int64_t>(s.at("images")) == static_cast<std::int64_t>(images.size()));
}

TEST_CASE("CameraNetworkActor: bad image options are ConfigErrors naming them",
          "[sim][actor][camera][camera_images]") {
  CameraNetworkOptions o = oneCamera();
  o.image_margin_m = -1;
  CHECK(configErrorOf(o).find("image_margin_m") != std::string::npos);
  o = oneCamera();
  o.image.blur_px = -1;
  CHECK(configErrorOf(o).find("option 'image.blur_px'") != std::string::npos);
  o = oneCamera();
  o.image.marker_id = 50;
  CHECK(configErrorOf(o).find("option 'image.marker_id'") != std::string::npos);
}

TEST_CASE("CameraImageRenderer: renderCameraImage's pixels, the floor made once",
          "[sim][camera_images]") {
  sim::CameraSite site;
  site.id = 2;
  site.position = {4.0, 1.0};
  site.yaw = 0.4;
  site.roll = -0.05;
  site.pitch = 0.03;
  const sim::EnvironmentCamera cam(site, sim::CameraIntrinsics{});
  sim::CameraImageOptions options;
  options.floor_texture_seed = 3;
  sim::CameraImageRenderer renderer(cam, options);
  std::mt19937_64 a(9), b(9);
  std::vector<std::uint8_t> buffer(640 * 480);
  cv::Mat wrapped(480, 640, CV_8UC1, buffer.data());  // memory the renderer does not own
  for (const tessera::Pose2& pose : {tessera::Pose2{4.2, 1.1, 0.3}, tessera::Pose2{3.1, 0.2, -2.0},
                                     tessera::Pose2{40.0, 40.0, 0.0}}) {
    const cv::Mat expected = sim::renderCameraImage(cam, pose, options, a);
    cv::Mat own;
    renderer.render(pose, b, own);
    REQUIRE(own.type() == CV_8UC1);
    REQUIRE(own.size() == expected.size());
    CHECK(cv::countNonZero(own != expected) == 0);
    // In place: the same pixels, written where the Mat points.
    const cv::Mat again = sim::renderCameraImage(cam, pose, options, a);
    renderer.render(pose, b, wrapped);
    CHECK(wrapped.data == buffer.data());
    CHECK(cv::countNonZero(wrapped != again) == 0);
  }
  CHECK_THROWS_AS(renderer.render(tessera::Pose2{std::nan(""), 0, 0}, b, wrapped),
                  std::invalid_argument);
}
