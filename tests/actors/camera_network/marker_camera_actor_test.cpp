// marker_camera through the mock-mailbox harness: a folder of rendered ceiling-camera frames
// (sim/camera_image.hpp) with the robot's marker passing through the view, another marker id, a
// missing source with reconnect back-off, bad options, an empty folder, an MJPG video file, and
// the same frames as msg::Image messages on a topic (frames that stop coming, late and unreadable
// images).
#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/image.capnp.h>
#include <tessera/camera_network/marker_camera_actor.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/sim/camera_image.hpp>
#include <tessera/sim/camera_network.hpp>

#include <catch2/catch.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "../../shared_data.hpp"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace marker_camera_actor_test {

using namespace tessera;
using tessera::camera_network::MarkerCameraActor;
using tessera::camera_network::MarkerCameraOptions;

constexpr Nanos kPeriod = 100'000'000;  // 10 fps

sim::EnvironmentCamera camera() {
  sim::CameraSite s;
  s.id = 3;
  s.position = {4.0, 0.0};
  s.yaw = 0.3;
  s.pitch = 0.04;
  return {s, sim::CameraIntrinsics{}};
}

/// What frame k shows: the robot's marker (id 7) at `pose`, another marker (id 3), or nothing.
struct Shot {
  enum class Kind { kNothing, kRobot, kOther } kind = Kind::kNothing;
  Pose2 pose;
};

/// 30 frames: 0-2 nothing, 3-4 marker id 3, 5-19 the robot's marker crossing the view (except
/// frame 12, nothing), 20-29 nothing.
std::vector<Shot> script() {
  const Eigen::Vector2d c = camera().site().position;
  std::vector<Shot> shots(30);
  for (int k = 3; k <= 4; ++k) shots[k] = {Shot::Kind::kOther, Pose2(c.x() - 0.5, c.y(), 0.2)};
  for (int k = 5; k <= 19; ++k) {
    const double s = (k - 5) / 14.0;  // 0 .. 1
    shots[k] = {Shot::Kind::kRobot, Pose2(c.x() - 1.5 + 3.0 * s, c.y() - 0.5 + s, 0.3 + 2.0 * s)};
  }
  shots[12] = {};
  return shots;
}

cv::Mat render(const Shot& shot, std::mt19937_64& rng) {
  sim::CameraImageOptions o;
  o.marker_id = shot.kind == Shot::Kind::kOther ? 3 : 7;
  // Nothing in view: the marker far outside the footprint (not drawn at all).
  const Pose2 pose = shot.kind == Shot::Kind::kNothing ? Pose2(60.0, 60.0, 0.0) : shot.pose;
  return sim::renderCameraImage(camera(), pose, o, rng);
}

std::int64_t figure(ActorHarness& h, const char* key) {
  Summary s;
  h.actor().summarize(s);
  return std::get<std::int64_t>(s.at(key));
}

std::string configErrorOf(const MarkerCameraOptions& o) {
  try {
    MarkerCameraActor a(o);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

void writeFolder(const std::filesystem::path& dir, const std::vector<Shot>& shots) {
  std::filesystem::create_directories(dir);
  std::mt19937_64 rng(11);
  char name[32];
  for (std::size_t k = 0; k < shots.size(); ++k) {
    std::snprintf(name, sizeof name, "frame_%03zu.png", k);
    REQUIRE(cv::imwrite((dir / name).string(), render(shots[k], rng)));
  }
  std::ofstream(dir / "notes.txt") << "not an image\n";
}

TEST_CASE("marker_camera: a folder of frames gives enter, detections, misses and leave",
          "[camera_network][marker_camera]") {
  const auto dir = test::scratchDir("marker_camera_folder");
  const auto shots = script();
  writeFolder(dir / "frames", shots);

  MarkerCameraOptions o;
  o.camera_id = 3;
  o.source = (dir / "frames").string();
  o.pixel_std = 0.7;
  ActorHarness h(std::make_unique<MarkerCameraActor>(o));
  const Nanos t0 = h.now();
  h.advance(0);  // frame 0 at t0
  for (std::size_t k = 1; k < shots.size(); ++k) h.advance(kPeriod);
  CHECK(figure(h, "source_finished") == 0);
  h.advance(kPeriod);  // past the last image: finished, not retried
  h.advance(5 * kPeriod);
  const auto stampOf = [&](std::size_t k) { return t0 + static_cast<Nanos>(k) * kPeriod; };

  const auto events = h.published<msg::CameraEvent>("camera_events");
  REQUIRE(events.size() == 2);
  CHECK(events[0]->getEntered());
  CHECK(events[0]->getHeader().getStampNs() == stampOf(5));
  CHECK_FALSE(events[1]->getEntered());
  CHECK(events[1]->getHeader().getStampNs() == stampOf(24));  // the 5th frame without it
  CHECK(events[1]->getCameraId() == 3);
  CHECK(std::string(events[0]->getHeader().getFrameId().cStr()) == "camera_3");

  const auto det = h.published<msg::MarkerDetection>("camera_detections");
  REQUIRE(det.size() == 19);  // frames 5-23
  const auto cam = camera();
  for (std::size_t i = 0; i < det.size(); ++i) {
    const std::size_t k = 5 + i;
    const auto& d = det[i];
    INFO("frame " << k);
    CHECK(d->getHeader().getStampNs() == stampOf(k));
    CHECK(std::string(d->getHeader().getFrameId().cStr()) == "camera_3");
    CHECK(d->getCameraId() == 3);
    CHECK(d->getPixelStd() == 0.7);
    if (shots[k].kind != Shot::Kind::kRobot) {
      CHECK_FALSE(d->getDetected());
      CHECK(d->getMarkerId() == -1);
      CHECK(d->getCorners().size() == 0);
      continue;
    }
    REQUIRE(d->getDetected());
    CHECK(d->getMarkerId() == 7);
    const Eigen::Vector2d truth = *cam.project(shots[k].pose.translation());
    CHECK(std::hypot(d->getU() - truth.x(), d->getV() - truth.y()) < 1.0);
    const auto corners = d->getCorners();
    REQUIRE(corners.size() == 8);
    const auto true_corners = *sim::markerCornerPixels(cam, shots[k].pose, 0.2);
    for (unsigned c = 0; c < 4; ++c)
      CHECK(std::hypot(corners[2 * c] - true_corners[c].x(),
                       corners[2 * c + 1] - true_corners[c].y()) < 1.5);
  }
  CHECK(figure(h, "frames") == 30);
  CHECK(figure(h, "detections") == 14);
  CHECK(figure(h, "misses") == 5);
  CHECK(figure(h, "other_markers") == 2);
  CHECK(figure(h, "events") == 2);
  CHECK(figure(h, "open_failures") == 0);
  CHECK(figure(h, "read_failures") == 0);
  CHECK(figure(h, "source_finished") == 1);
  h.stop();
  std::filesystem::remove_all(dir);
}

TEST_CASE("marker_camera: a missing source is retried with back-off and never throws",
          "[camera_network][marker_camera]") {
  const auto dir = test::scratchDir("marker_camera_missing");
  SECTION("a video file") {
    MarkerCameraOptions o;
    o.source = "/nonexistent/video.mp4";
    ActorHarness h(std::make_unique<MarkerCameraActor>(o));
    REQUIRE_NOTHROW(h.advance(0));
    for (int k = 0; k < 40; ++k) REQUIRE_NOTHROW(h.advance(kPeriod));  // 4 s
    CHECK(figure(h, "open_failures") == 3);  // at 0, 1 and 3 s; next at 7 s
    CHECK(figure(h, "reconnects") == 0);
    CHECK(figure(h, "frames") == 0);
    CHECK(h.publishedCount("camera_events") == 0);
    CHECK(h.publishedCount("camera_detections") == 0);
    h.stop();
  }
  SECTION("a folder that appears later") {
    MarkerCameraOptions o;
    o.source = (dir / "later").string();
    ActorHarness h(std::make_unique<MarkerCameraActor>(o));
    h.advance(0);
    for (int k = 0; k < 15; ++k) h.advance(kPeriod);  // 1.5 s: failed at 0 and 1 s
    CHECK(figure(h, "open_failures") == 2);
    writeFolder(dir / "later", script());
    for (int k = 0; k < 28; ++k) h.advance(kPeriod);  // opened at 3 s, frames to 4.3 s
    CHECK(figure(h, "open_failures") == 2);
    CHECK(figure(h, "reconnects") == 1);
    const std::int64_t frames = figure(h, "frames");  // 3.1 .. 4.3 s, and 3.0 s if opened first
    CHECK((frames == 13 || frames == 14));
    h.stop();
  }
  std::filesystem::remove_all(dir);
}

TEST_CASE("marker_camera: bad options are ConfigErrors naming the option",
          "[camera_network][marker_camera]") {
  MarkerCameraOptions good;
  good.source = "/dev/video0";
  CHECK(configErrorOf(good).empty());
  auto bad = [&](auto change) {
    MarkerCameraOptions o = good;
    change(o);
    return configErrorOf(o);
  };
  CHECK_THAT(bad([](auto& o) { o.source.clear(); }), Catch::Contains("source"));
  CHECK_THAT(bad([](auto& o) { o.fps = 0; }), Catch::Contains("fps"));
  CHECK_THAT(bad([](auto& o) { o.fps = std::nan(""); }), Catch::Contains("fps"));
  CHECK_THAT(bad([](auto& o) { o.leave_after_misses = 0; }), Catch::Contains("leave_after_misses"));
  CHECK_THAT(bad([](auto& o) { o.pixel_std = -1; }), Catch::Contains("pixel_std"));
  CHECK_THAT(bad([](auto& o) { o.marker_id = -2; }), Catch::Contains("marker_id"));
  CHECK_THAT(bad([](auto& o) { o.retry_initial_s = 0; }), Catch::Contains("retry_initial_s"));
  CHECK_THAT(bad([](auto& o) { o.retry_max_s = 0.5; }), Catch::Contains("retry_max_s"));
  CHECK_THAT(bad([](auto& o) { o.detector.dictionary = "9x9_1"; }), Catch::Contains("detector"));
}

TEST_CASE("marker_camera: a folder without images is an error naming it at start",
          "[camera_network][marker_camera]") {
  const auto dir = test::scratchDir("marker_camera_empty");
  std::ofstream(dir / "readme.txt") << "no images here\n";
  MarkerCameraOptions o;
  o.source = dir.string();
  ActorHarness h(std::make_unique<MarkerCameraActor>(o));  // constructing is fine
  CHECK_THROWS_WITH(h.advance(0), Catch::Contains(dir.string()) && Catch::Contains("no images"));
  std::filesystem::remove_all(dir);
}

TEST_CASE("marker_camera: an MJPG video file is read to its end, then finished",
          "[camera_network][marker_camera]") {
  const auto dir = test::scratchDir("marker_camera_video");
  const auto file = (dir / "pass.avi").string();
  const auto shots = script();
  {
    cv::VideoWriter writer;
    if (!writer.open(file, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0, cv::Size(640, 480),
                     /*isColor=*/true))
      return;  // no MJPG/AVI writer in this OpenCV build: the folder tests cover the actor
    std::mt19937_64 rng(5);
    for (int k = 0; k < 10; ++k) {  // frames 3-12 of the script: ends with the marker in view
      const cv::Mat grey = render(shots[3 + static_cast<std::size_t>(k)], rng);
      cv::Mat bgr;
      cv::merge(std::vector<cv::Mat>{grey, grey, grey}, bgr);
      writer.write(bgr);
    }
  }
  MarkerCameraOptions o;
  o.source = file;
  ActorHarness h(std::make_unique<MarkerCameraActor>(o));
  h.advance(0);
  for (int k = 0; k < 15; ++k) h.advance(kPeriod);
  if (figure(h, "open_failures") > 0) return;  // no backend reads it back here
  CHECK(figure(h, "frames") == 10);
  CHECK(figure(h, "other_markers") == 2);
  CHECK(figure(h, "detections") == 7);  // script frames 5-11
  CHECK(figure(h, "misses") == 1);      // script frame 12
  CHECK(figure(h, "source_finished") == 1);
  const auto events = h.published<msg::CameraEvent>("camera_events");
  REQUIRE(events.size() == 2);  // enter, and leave when the video ends
  CHECK(events[0]->getEntered());
  CHECK_FALSE(events[1]->getEntered());
  const auto cam = camera();
  std::size_t k = 5;  // the script frame of the next detection
  for (const auto& d : h.published<msg::MarkerDetection>("camera_detections")) {
    if (!d->getDetected()) continue;
    CHECK(d->getMarkerId() == 7);
    CHECK(d->getCorners().size() == 8);
    const Eigen::Vector2d truth = *cam.project(shots[k++].pose.translation());
    CHECK(std::hypot(d->getU() - truth.x(), d->getV() - truth.y()) < 2.0);  // MJPG artefacts
  }
  h.stop();
  std::filesystem::remove_all(dir);
}

/// Publishes `grey` on the topic camera_images as a msg::Image (its stamp, frame id and
/// encoding as given) and lets the actor handle it.
void pushImage(ActorHarness& h, const cv::Mat& grey, Nanos stamp, const std::string& frame,
               const char* encoding = "mono8", std::size_t drop_bytes = 0) {
  h.push<msg::Image>("camera_images", [&](msg::Image::Builder b) {
    setHeader(b.initHeader(), stamp, frame, 0);
    b.setWidth(static_cast<std::uint32_t>(grey.cols));
    b.setHeight(static_cast<std::uint32_t>(grey.rows));
    b.setEncoding(encoding);
    b.setStep(static_cast<std::uint32_t>(grey.cols));
    const std::size_t bytes = grey.total() - drop_bytes;
    auto data = b.initData(static_cast<unsigned>(bytes));
    std::memcpy(data.begin(), grey.data, bytes);
  });
  h.runUntilIdle();
}

MarkerCameraOptions topicOptions() {
  MarkerCameraOptions o;
  o.camera_id = 3;
  o.source = "topic:camera_images";
  return o;
}

TEST_CASE("marker_camera: a topic source takes its camera's images, stamped by the images",
          "[camera_network][marker_camera][camera_images]") {
  const auto shots = script();
  std::mt19937_64 rng(11);
  std::vector<cv::Mat> frames;
  for (const auto& shot : shots) frames.push_back(render(shot, rng));
  // Stamps of the images, 1 s ahead of the actor's clock: the messages carry the image stamps.
  ActorHarness h(std::make_unique<MarkerCameraActor>(topicOptions()));
  h.advance(0);
  const Nanos t0 = h.now() + kNanosPerSecond;
  const auto stampOf = [&](std::size_t k) { return t0 + static_cast<Nanos>(k) * kPeriod; };
  const auto cam = camera();

  SECTION("frames keep coming after the marker left: the 5th without it is the leave") {
    for (std::size_t k = 0; k < shots.size(); ++k) {
      pushImage(h, frames[k], stampOf(k), "camera_3");
      // Another camera's image (here the same pixels, marker and all) is not this camera's.
      pushImage(h, frames[k], stampOf(k), "camera_5");
    }
    const auto events = h.published<msg::CameraEvent>("camera_events");
    REQUIRE(events.size() == 2);
    CHECK(events[0]->getEntered());
    CHECK(events[0]->getHeader().getStampNs() == stampOf(5));
    CHECK_FALSE(events[1]->getEntered());
    CHECK(events[1]->getHeader().getStampNs() == stampOf(24));
    CHECK(events[1]->getCameraId() == 3);
    const auto det = h.published<msg::MarkerDetection>("camera_detections");
    REQUIRE(det.size() == 19);  // frames 5-23
    for (std::size_t i = 0; i < det.size(); ++i) {
      const std::size_t k = 5 + i;
      INFO("frame " << k);
      CHECK(det[i]->getHeader().getStampNs() == stampOf(k));
      CHECK(std::string(det[i]->getHeader().getFrameId().cStr()) == "camera_3");
      if (shots[k].kind != Shot::Kind::kRobot) {
        CHECK_FALSE(det[i]->getDetected());
        continue;
      }
      REQUIRE(det[i]->getDetected());
      CHECK(det[i]->getMarkerId() == 7);
      CHECK(det[i]->getCorners().size() == 8);
      const Eigen::Vector2d truth = *cam.project(shots[k].pose.translation());
      CHECK(std::hypot(det[i]->getU() - truth.x(), det[i]->getV() - truth.y()) < 1.0);
    }
    h.advance(50 * kPeriod);  // no frames for 5 s: nothing more (the leave was published)
    CHECK(h.publishedCount("camera_events") == 2);
    CHECK(figure(h, "frames") == 30);
    CHECK(figure(h, "detections") == 14);
    CHECK(figure(h, "misses") == 5);
    CHECK(figure(h, "other_markers") == 2);
    CHECK(figure(h, "leaves_without_frames") == 0);
    CHECK(figure(h, "late_frames") == 0);
  }

  SECTION("frames stop with the marker in view: the leave comes when the frames are missed") {
    for (std::size_t k = 0; k <= 16; ++k) pushImage(h, frames[k], stampOf(k), "camera_3");
    // Frame 16 shows the marker; frames 17... never come. The leave is due where the 5th missing
    // frame would be (frame 21), and is published one frame period after that.
    h.advance(21 * kPeriod);  // the clock at stampOf(11): nothing due yet
    REQUIRE(h.publishedCount("camera_events") == 1);
    h.advance(10 * kPeriod);  // stampOf(21)
    CHECK(h.publishedCount("camera_events") == 1);
    h.advance(kPeriod);  // stampOf(22)
    const auto events = h.published<msg::CameraEvent>("camera_events");
    REQUIRE(events.size() == 2);
    CHECK_FALSE(events[1]->getEntered());
    CHECK(events[1]->getHeader().getStampNs() == stampOf(21));
    CHECK(figure(h, "leaves_without_frames") == 1);
    // A frame from before the leave is late and skipped; a newer one is handled (and here shows
    // the marker again: a fresh entry).
    pushImage(h, frames[17], stampOf(17), "camera_3");
    CHECK(figure(h, "late_frames") == 1);
    pushImage(h, frames[18], stampOf(22), "camera_3");
    const auto after = h.published<msg::CameraEvent>("camera_events");
    REQUIRE(after.size() == 3);
    CHECK(after[2]->getEntered());
    CHECK(after[2]->getHeader().getStampNs() == stampOf(22));
    CHECK(figure(h, "frames") == 18);
  }

  SECTION("images it cannot read are read failures, skipped") {
    pushImage(h, frames[6], stampOf(0), "camera_3", "32FC1");
    pushImage(h, frames[6], stampOf(1), "camera_3", "mono8", 640);  // a row short
    CHECK(figure(h, "read_failures") == 2);
    CHECK(figure(h, "frames") == 0);
    pushImage(h, frames[6], stampOf(2), "camera_3");
    CHECK(figure(h, "frames") == 1);
    CHECK(figure(h, "detections") == 1);
    // rgb8 and bgr8 are taken too.
    cv::Mat bgr;
    cv::merge(std::vector<cv::Mat>{frames[7], frames[7], frames[7]}, bgr);
    h.push<msg::Image>("camera_images", [&](msg::Image::Builder b) {
      setHeader(b.initHeader(), stampOf(3), "camera_3", 0);
      b.setWidth(640);
      b.setHeight(480);
      b.setEncoding("rgb8");
      b.setStep(640 * 3);
      auto data = b.initData(static_cast<unsigned>(bgr.total() * 3));
      std::memcpy(data.begin(), bgr.data, bgr.total() * 3);
    });
    h.runUntilIdle();
    CHECK(figure(h, "detections") == 2);
    CHECK(figure(h, "read_failures") == 2);
  }
  h.stop();
}

TEST_CASE("marker_camera: a topic source needs a topic name", "[camera_network][marker_camera]") {
  MarkerCameraOptions o = topicOptions();
  o.source = "topic:";
  CHECK_THAT(configErrorOf(o), Catch::Contains("source"));
  o = topicOptions();
  o.image_queue = 0;
  CHECK_THAT(configErrorOf(o), Catch::Contains("image_queue"));
}

}  // namespace marker_camera_actor_test
