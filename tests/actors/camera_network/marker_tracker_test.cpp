// MarkerTracker and MarkerDetector::detect(image, window) (camera_network/marker_detector.hpp) on
// the simulator's rendered ceiling-camera images: the marker followed along a drive from a window
// around its last detection, the whole image searched again after a jump or a loss, windows
// clipped at the image's borders, and the new options checked.
#include <tessera/camera_network/marker_detector.hpp>
#include <tessera/sim/camera_image.hpp>
#include <tessera/sim/camera_network.hpp>

#include <catch2/catch.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace camera_network_marker_tracker_test {

using tessera::Pose2;
using tessera::camera_network::DetectedMarker;
using tessera::camera_network::MarkerDetector;
using tessera::camera_network::MarkerDetectorOptions;
using tessera::camera_network::MarkerTracker;
using tessera::sim::CameraImageOptions;
using tessera::sim::EnvironmentCamera;

constexpr int kRobotId = 7;

EnvironmentCamera trackerCamera() {
  tessera::sim::CameraSite site;
  site.id = 4;
  site.position = {2.0, 1.0};
  site.yaw = 0.4;
  site.roll = 0.03;
  site.pitch = -0.02;
  return {site, tessera::sim::CameraIntrinsics{}};
}

/// The marker pose whose centre projects at pixel (u, v).
Pose2 poseAtPixel(const EnvironmentCamera& cam, double u, double v, double heading) {
  return {cam.floorPoint({u, v}), heading};
}

cv::Mat render(const EnvironmentCamera& cam, const Pose2& pose, std::mt19937_64& rng) {
  return tessera::sim::renderCameraImage(cam, pose, CameraImageOptions{}, rng);
}

/// The robot's marker, by value: callers pass temporaries (a pointer into them would dangle).
std::optional<DetectedMarker> robotIn(const std::vector<DetectedMarker>& markers) {
  for (const auto& m : markers)
    if (m.id == kRobotId) return m;
  return std::nullopt;
}

double centreError(const EnvironmentCamera& cam, const Pose2& pose, const DetectedMarker& m) {
  return (m.centre - *cam.project(pose.translation())).norm();
}

bool inside(const cv::Rect& window, const DetectedMarker& m) {
  for (const Eigen::Vector2d& c : m.corners)
    if (!window.contains(
            cv::Point(static_cast<int>(std::lround(c.x())), static_cast<int>(std::lround(c.y())))))
      return false;
  return true;
}

TEST_CASE("the tracker follows a driving robot's marker from windows, as the whole image finds it",
          "[camera_network][marker_tracker]") {
  const auto cam = trackerCamera();
  const MarkerDetector detector;
  MarkerTracker tracker(detector, kRobotId);
  std::mt19937_64 rng(3);
  // 0.3 m/s at 10 Hz, gently turning, from the left of the view to the right.
  Pose2 pose = poseAtPixel(cam, 120, 260, 0.0);
  pose.theta =
      std::atan2(cam.floorPoint({500, 220}).y() - pose.y, cam.floorPoint({500, 220}).x() - pose.x);
  int from_window = 0;
  const int frames = 60;
  for (int k = 0; k < frames; ++k) {
    INFO("frame " << k);
    const cv::Mat image = render(cam, pose, rng);
    const auto markers = tracker.detect(image);
    std::optional<DetectedMarker> m = robotIn(markers);
    REQUIRE(m.has_value());
    CHECK(centreError(cam, pose, *m) < 1.0);
    REQUIRE(tracker.last());
    CHECK(tracker.last()->centre == m->centre);
    if (k == 0) {
      CHECK(tracker.lastWindow().empty());  // nothing to start from: the whole image
      CHECK_FALSE(tracker.answeredFromWindow());
    } else {
      CHECK(inside(tracker.lastWindow(), *m));
      // The window holds about the marker and a side of margin around it: a small part of the
      // image.
      CHECK(tracker.lastWindow().area() < image.cols * image.rows / 20);
    }
    from_window += tracker.answeredFromWindow();
    // The window's answer is the whole image's.
    const std::optional<DetectedMarker> whole = robotIn(detector.detect(image));
    REQUIRE(whole.has_value());
    for (std::size_t c = 0; c < 4; ++c) CHECK((whole->corners[c] - m->corners[c]).norm() < 0.01);
    pose = Pose2(
        pose.translation() + 0.03 * Eigen::Vector2d(std::cos(pose.theta), std::sin(pose.theta)),
        pose.theta + 0.005);
  }
  CHECK(from_window == frames - 1);
}

TEST_CASE("after a jump or a loss the tracker searches the whole image",
          "[camera_network][marker_tracker]") {
  const auto cam = trackerCamera();
  MarkerTracker tracker(MarkerDetector{}, kRobotId);
  std::mt19937_64 rng(5);
  const Pose2 first = poseAtPixel(cam, 200, 150, 0.5);
  REQUIRE(robotIn(tracker.detect(render(cam, first, rng))));
  REQUIRE(robotIn(tracker.detect(render(cam, first, rng))));
  CHECK(tracker.answeredFromWindow());

  // The marker jumps across the image: the window around the old place is tried and misses, the
  // whole image finds it.
  const Pose2 jumped = poseAtPixel(cam, 480, 380, -1.0);
  std::optional<DetectedMarker> m = robotIn(tracker.detect(render(cam, jumped, rng)));
  REQUIRE(m.has_value());
  CHECK(centreError(cam, jumped, *m) < 1.0);
  CHECK_FALSE(tracker.answeredFromWindow());
  CHECK(tracker.lastWindow().contains(cv::Point(200, 150)));  // around the old place
  CHECK_FALSE(inside(tracker.lastWindow(), *m));
  // The next frame is answered from a window around the new place.
  m = robotIn(tracker.detect(render(cam, jumped, rng)));
  REQUIRE(m.has_value());
  CHECK(tracker.answeredFromWindow());
  CHECK(inside(tracker.lastWindow(), *m));

  // The marker leaves the view: no detection, and the tracker forgets it.
  const Pose2 gone(cam.site().position + Eigen::Vector2d(50.0, 0.0), 0.0);
  CHECK(tracker.detect(render(cam, gone, rng)).empty());
  CHECK_FALSE(tracker.last());
  CHECK_FALSE(tracker.answeredFromWindow());
  // It comes back: found in the whole image (no window to try).
  REQUIRE(robotIn(tracker.detect(render(cam, first, rng))));
  CHECK(tracker.lastWindow().empty());
  CHECK_FALSE(tracker.answeredFromWindow());

  // reset() forgets the last detection too.
  tracker.reset();
  CHECK_FALSE(tracker.last());
  REQUIRE(robotIn(tracker.detect(render(cam, first, rng))));
  CHECK(tracker.lastWindow().empty());
}

TEST_CASE("windows are clipped at the image's borders and corners",
          "[camera_network][marker_tracker]") {
  const auto cam = trackerCamera();
  const cv::Rect image_rect(0, 0, cam.intrinsics().width_px, cam.intrinsics().height_px);
  std::mt19937_64 rng(7);
  for (const auto& [u, v] : {std::pair{22.0, 22.0}, std::pair{617.0, 240.0},
                             std::pair{320.0, 457.0}, std::pair{617.0, 457.0}}) {
    INFO("marker at pixel " << u << ", " << v);
    const Pose2 pose = poseAtPixel(cam, u, v, 0.0);
    MarkerTracker tracker(MarkerDetector{}, kRobotId);
    REQUIRE(robotIn(tracker.detect(render(cam, pose, rng))));
    std::optional<DetectedMarker> m = robotIn(tracker.detect(render(cam, pose, rng)));
    REQUIRE(m.has_value());
    CHECK(tracker.answeredFromWindow());
    CHECK(centreError(cam, pose, *m) < 1.0);
    const cv::Rect window = tracker.lastWindow();
    CHECK((window & image_rect) == window);
    CHECK((window.x == 0 || window.y == 0 || window.br().x == image_rect.width ||
           window.br().y == image_rect.height));
    CHECK(inside(window, *m));
  }
}

TEST_CASE("a zero track margin searches the whole image every frame",
          "[camera_network][marker_tracker]") {
  const auto cam = trackerCamera();
  MarkerDetectorOptions o;
  o.track_margin = 0;
  MarkerTracker tracker(MarkerDetector(o), kRobotId);
  std::mt19937_64 rng(9);
  const Pose2 pose = poseAtPixel(cam, 300, 200, 2.0);
  for (int k = 0; k < 3; ++k) {
    REQUIRE(robotIn(tracker.detect(render(cam, pose, rng))));
    CHECK(tracker.lastWindow().empty());
    CHECK_FALSE(tracker.answeredFromWindow());
  }
}

TEST_CASE("detect in a window: only its markers, in the whole image's pixels",
          "[camera_network][marker_detector]") {
  const auto cam = trackerCamera();
  const MarkerDetector detector;
  std::mt19937_64 rng(11);
  const Pose2 pose = poseAtPixel(cam, 400, 300, 1.2);
  const cv::Mat grey = render(cam, pose, rng);
  cv::Mat colour;
  cv::cvtColor(grey, colour, cv::COLOR_GRAY2BGR);
  const Eigen::Vector2d truth = *cam.project(pose.translation());
  for (const cv::Mat& image : {grey, colour}) {
    const auto markers = detector.detect(image, cv::Rect(340, 240, 120, 120));
    REQUIRE(markers.size() == 1);
    CHECK(markers[0].id == kRobotId);
    CHECK((markers[0].centre - truth).norm() < 1.0);
    // A window reaching past the image is clipped.
    CHECK(detector.detect(image, cv::Rect(300, 200, 1000, 1000)).size() == 1);
    // Windows without the marker, or outside the image, find nothing.
    CHECK(detector.detect(image, cv::Rect(0, 0, 200, 200)).empty());
    CHECK(detector.detect(image, cv::Rect(700, 10, 50, 50)).empty());
    CHECK(detector.detect(image, cv::Rect(340, 240, 0, 120)).empty());
  }
  CHECK_THROWS_WITH(detector.detect(cv::Mat(), cv::Rect(0, 0, 10, 10)), Catch::Contains("empty"));
  CHECK_THROWS_WITH(detector.detect(cv::Mat(480, 640, CV_16UC1, cv::Scalar(0)), cv::Rect()),
                    Catch::Contains("CV_16U"));
}

TEST_CASE("bad threshold windows and track margins are refused, naming the option",
          "[camera_network][marker_detector]") {
  const auto error = [](void (*change)(MarkerDetectorOptions&)) -> std::string {
    MarkerDetectorOptions o;
    change(o);
    try {
      MarkerDetector d(o);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "";
  };
  CHECK_THAT(error([](MarkerDetectorOptions& o) { o.threshold_window_min_px = 2; }),
             Catch::Contains("threshold_window_min_px"));
  CHECK_THAT(error([](MarkerDetectorOptions& o) { o.threshold_window_max_px = 5; }),
             Catch::Contains("threshold_window_max_px"));
  CHECK_THAT(error([](MarkerDetectorOptions& o) { o.threshold_window_step_px = 0; }),
             Catch::Contains("threshold_window_step_px"));
  CHECK_THAT(error([](MarkerDetectorOptions& o) { o.track_margin = -1; }),
             Catch::Contains("track_margin"));
  CHECK_THAT(error([](MarkerDetectorOptions& o) { o.track_margin = std::nan(""); }),
             Catch::Contains("track_margin"));
  // OpenCV's own three windows are still there to choose.
  CHECK(error([](MarkerDetectorOptions& o) {
          o.threshold_window_min_px = 3;
          o.threshold_window_max_px = 23;
        }).empty());
}

}  // namespace camera_network_marker_tracker_test
