// ArUco marker detection (camera_network/marker_detector.hpp) in the simulator's rendered
// ceiling-camera images (sim/camera_image.hpp), against the true projected marker corners.
#include <tessera/camera_network/marker_detector.hpp>
#include <tessera/sim/camera_image.hpp>
#include <tessera/sim/camera_network.hpp>

#include <catch2/catch.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <random>
#include <utility>
#include <vector>

namespace camera_network_marker_detector_test {

using tessera::Pose2;
using tessera::camera_network::DetectedMarker;
using tessera::camera_network::MarkerDetector;
using tessera::camera_network::MarkerDetectorOptions;
using tessera::sim::CameraImageOptions;
using tessera::sim::CameraSite;
using tessera::sim::EnvironmentCamera;
using tessera::sim::markerCornerPixels;
using tessera::sim::renderCameraImage;

EnvironmentCamera markerCamera(double roll, double pitch) {
  CameraSite site;
  site.id = 2;
  site.position = {4.0, -2.5};
  site.yaw = 0.6;
  site.roll = roll;
  site.pitch = pitch;
  return {site, tessera::sim::CameraIntrinsics{}};
}

/// A random marker pose whose printed square with its quiet zone (and some more) projects at
/// least `margin_px` inside the image.
Pose2 randomPoseInView(const EnvironmentCamera& cam, double marker_size, double margin_px,
                       std::mt19937_64& rng) {
  const double w = cam.intrinsics().width_px, h = cam.intrinsics().height_px;
  std::uniform_real_distribution<double> u(0, w), v(0, h), heading(-M_PI, M_PI);
  for (;;) {
    const Pose2 pose(cam.floorPoint({u(rng), v(rng)}), heading(rng));
    const auto outline = markerCornerPixels(cam, pose, 1.5 * marker_size);
    if (!outline) continue;
    bool inside = true;
    for (const Eigen::Vector2d& p : *outline)
      inside = inside && p.x() >= margin_px && p.y() >= margin_px && p.x() <= w - 1 - margin_px &&
               p.y() <= h - 1 - margin_px;
    if (inside) return pose;
  }
}

const DetectedMarker* findId(const std::vector<DetectedMarker>& markers, int id) {
  for (const auto& m : markers)
    if (m.id == id) return &m;
  return nullptr;
}

struct Accuracy {
  int frames = 0, found = 0, other_ids = 0;
  double corner_sq = 0, max_centre_error = 0;
  int corners = 0;
  double cornerRms() const { return corners > 0 ? std::sqrt(corner_sq / corners) : 0.0; }
};

Accuracy measure(const EnvironmentCamera& cam, int frames, std::uint64_t seed) {
  const MarkerDetector detector;
  const CameraImageOptions options;
  std::mt19937_64 rng(seed);
  Accuracy a;
  for (a.frames = 0; a.frames < frames; ++a.frames) {
    const Pose2 pose = randomPoseInView(cam, options.marker_size_m, 8.0, rng);
    const cv::Mat image = renderCameraImage(cam, pose, options, rng);
    const auto markers = detector.detect(image);
    for (const auto& m : markers) a.other_ids += m.id != options.marker_id;
    const DetectedMarker* m = findId(markers, options.marker_id);
    if (!m) continue;
    ++a.found;
    const auto truth = *markerCornerPixels(cam, pose, options.marker_size_m);
    for (std::size_t k = 0; k < 4; ++k) {
      a.corner_sq += (m->corners[k] - truth[k]).squaredNorm();
      ++a.corners;
    }
    const double centre_error = (m->centre - *cam.project(pose.translation())).norm();
    a.max_centre_error = std::max(a.max_centre_error, centre_error);
  }
  return a;
}

TEST_CASE("the robot's marker is found in rendered images of untilted and tilted cameras",
          "[camera_network][marker_detector]") {
  for (const auto& [roll, pitch] : {std::pair{0.0, 0.0}, std::pair{0.1, -0.1}}) {
    const auto cam = markerCamera(roll, pitch);
    const Accuracy a = measure(cam, 50, 11);
    INFO("roll " << roll << " pitch " << pitch << ": found " << a.found << "/" << a.frames
                 << ", corner RMS " << a.cornerRms() << " px, max centre error "
                 << a.max_centre_error << " px");
    CHECK(a.found >= 48);  // >= 95 %
    CHECK(a.other_ids == 0);
    CHECK(a.cornerRms() < 1.5);
    CHECK(a.max_centre_error < 1.0);
  }
}

TEST_CASE("another marker is reported with its own id, also in a colour image",
          "[camera_network][marker_detector]") {
  const auto cam = markerCamera(0.1, 0.08);
  CameraImageOptions options;
  options.marker_id = 3;
  std::mt19937_64 rng(5);
  const Pose2 pose = randomPoseInView(cam, options.marker_size_m, 8.0, rng);
  const cv::Mat grey = renderCameraImage(cam, pose, options, rng);
  cv::Mat colour;
  cv::cvtColor(grey, colour, cv::COLOR_GRAY2BGR);
  const MarkerDetector detector;
  for (const cv::Mat& image : {grey, colour}) {
    const auto markers = detector.detect(image);
    REQUIRE(markers.size() == 1);
    CHECK(markers[0].id == 3);
    CHECK((markers[0].centre - *cam.project(pose.translation())).norm() < 1.0);
  }
}

TEST_CASE("images without a marker give no detections", "[camera_network][marker_detector]") {
  const auto cam = markerCamera(0.05, 0.1);
  const MarkerDetector detector;
  std::mt19937_64 rng(9);
  const Pose2 far_away(cam.site().position + Eigen::Vector2d(100.0, 0.0), 0.0);
  for (int seed = 1; seed <= 4; ++seed) {
    CameraImageOptions options;
    options.floor_texture_seed = seed;
    CHECK(detector.detect(renderCameraImage(cam, far_away, options, rng)).empty());
  }
  CHECK(detector.detect(cv::Mat(480, 640, CV_8UC1, cv::Scalar(128))).empty());
}

TEST_CASE("the floor is the same in every frame and only the noise is random",
          "[camera_network][marker_detector]") {
  const auto cam = markerCamera(0.1, -0.1);
  CameraImageOptions quiet;
  quiet.noise_std = 0;
  std::mt19937_64 rng(1);
  const cv::Mat a = renderCameraImage(cam, Pose2(cam.site().position, 0.3), quiet, rng);
  const cv::Mat b = renderCameraImage(cam, Pose2(cam.site().position, 0.3), quiet, rng);
  REQUIRE(a.type() == CV_8UC1);
  REQUIRE(a.rows == 480);
  REQUIRE(a.cols == 640);
  CHECK(cv::countNonZero(a != b) == 0);
  // With noise the frames differ, but not by much.
  const cv::Mat c = renderCameraImage(cam, Pose2(cam.site().position, 0.3), {}, rng);
  cv::Mat diff;
  cv::absdiff(a, c, diff);
  CHECK(cv::countNonZero(diff) > 0);
  CHECK(cv::mean(diff)[0] < 4.0);
  // Another texture seed is another floor.
  CameraImageOptions other = quiet;
  other.floor_texture_seed = 2;
  cv::absdiff(a, renderCameraImage(cam, Pose2(cam.site().position, 0.3), other, rng), diff);
  CHECK(cv::mean(diff)[0] > 4.0);
}

TEST_CASE("bad images, dictionaries and render options are refused with a clear message",
          "[camera_network][marker_detector]") {
  const MarkerDetector detector;
  CHECK_THROWS_WITH(detector.detect(cv::Mat()), Catch::Contains("empty"));
  CHECK_THROWS_WITH(detector.detect(cv::Mat(480, 640, CV_32FC1, cv::Scalar(0))),
                    Catch::Contains("CV_8UC1 or CV_8UC3") && Catch::Contains("CV_32F"));
  CHECK_THROWS_WITH(detector.detect(cv::Mat(480, 640, CV_8UC4, cv::Scalar(0))),
                    Catch::Contains("CV_8UC4"));

  for (const char* name : {"4x4_50", "5x5_100", "6x6_250"}) {
    MarkerDetectorOptions o;
    o.dictionary = name;
    CHECK_NOTHROW(MarkerDetector(o));
  }
  MarkerDetectorOptions bad;
  bad.dictionary = "4x4_51";
  CHECK_THROWS_WITH(MarkerDetector(bad),
                    Catch::Contains("dictionary") && Catch::Contains("\"4x4_51\""));

  const auto cam = markerCamera(0, 0);
  std::mt19937_64 rng(1);
  CameraImageOptions options;
  options.marker_id = 50;
  CHECK_THROWS_WITH(renderCameraImage(cam, Pose2(), options, rng), Catch::Contains("marker_id"));
  options = {};
  options.marker_size_m = 0;
  CHECK_THROWS_WITH(renderCameraImage(cam, Pose2(), options, rng),
                    Catch::Contains("marker_size_m"));
}

}  // namespace camera_network_marker_detector_test
