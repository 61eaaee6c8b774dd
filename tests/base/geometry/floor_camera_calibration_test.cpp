// Tests for the stored floor-plane camera calibration and its validity check.
#include <tessera/geometry/floor_camera_calibration.hpp>

#include <catch2/catch.hpp>

#include <limits>

using Catch::Matchers::StartsWith;
using tessera::FloorCameraCalibration;
using tessera::floorCameraCalibrationProblem;

namespace {

FloorCameraCalibration valid() {
  FloorCameraCalibration c;
  c.camera = 3;
  c.submap = 1;
  c.stamp_ns = 42;
  c.floor_to_pixel << 80, 0, 320, 0, -80, 240, 0, 0.001, 1;
  c.rms_px = 0.9;
  c.coverage = 0.3;
  c.condition = 2e3;
  c.pairs = 40;
  c.inliers = 38;
  return c;
}

}  // namespace

TEST_CASE("floor camera calibration that is valid has no problem", "[geometry][floor_camera]") {
  CHECK(floorCameraCalibrationProblem(valid()).empty());
  FloorCameraCalibration edge = valid();
  edge.coverage = 1;
  edge.rms_px = 0;
  edge.inliers = edge.pairs;
  CHECK(floorCameraCalibrationProblem(edge).empty());
}

TEST_CASE("floor camera calibration problems name the stored key", "[geometry][floor_camera]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const auto problem = [](auto change) {
    FloorCameraCalibration c = valid();
    change(c);
    return floorCameraCalibrationProblem(c);
  };
  CHECK_THAT(problem([](auto& c) { c.camera = -1; }), StartsWith("id: must be >= 0, got -1"));
  CHECK_THAT(problem([](auto& c) { c.submap = -2; }), StartsWith("submap: must be >= 0"));
  CHECK_THAT(problem([&](auto& c) { c.floor_to_pixel(1, 2) = nan; }),
             StartsWith("homography: must be 9 finite numbers"));
  CHECK_THAT(problem([](auto& c) { c.floor_to_pixel << 1, 2, 3, 2, 4, 6, 0, 0, 1; }),
             StartsWith("homography: is singular"));
  CHECK_THAT(problem([](auto& c) { c.floor_to_pixel.setZero(); }),
             StartsWith("homography: is singular"));
  CHECK_THAT(problem([&](auto& c) { c.rms_px = nan; }), StartsWith("rms_px: must be a finite"));
  CHECK_THAT(problem([](auto& c) { c.rms_px = -0.1; }), StartsWith("rms_px: must be a finite"));
  CHECK_THAT(problem([](auto& c) { c.coverage = 1.5; }), StartsWith("coverage: must be in 0..1"));
  CHECK_THAT(problem([&](auto& c) { c.coverage = nan; }), StartsWith("coverage: must be in 0..1"));
  CHECK_THAT(problem([](auto& c) { c.condition = -1; }), StartsWith("condition: must be"));
  CHECK_THAT(problem([](auto& c) { c.pairs = -1; }), StartsWith("pairs: must be >= 0"));
  CHECK_THAT(problem([](auto& c) { c.inliers = 41; }),
             StartsWith("inliers: must be in 0..pairs (40), got 41"));
}

TEST_CASE("floor camera homography inverse condition", "[geometry][floor_camera]") {
  CHECK(tessera::homographyInverseCondition(Eigen::Matrix3d::Identity()) == 1.0);
  CHECK(tessera::homographyInverseCondition(Eigen::Matrix3d::Zero()) == 0.0);
  const Eigen::Matrix3d d = Eigen::Vector3d(4, 2, 1).asDiagonal();
  CHECK(tessera::homographyInverseCondition(d) == 0.25);
}
