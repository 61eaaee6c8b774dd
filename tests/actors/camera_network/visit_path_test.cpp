// A calibration visit's odometry path refined with the camera's pixels
// (camera_network/visit_path.hpp), against the simulator's true camera and noisy odometry.
#include <tessera/camera_network/camera_localization.hpp>
#include <tessera/camera_network/floor_homography.hpp>
#include <tessera/camera_network/visit_path.hpp>
#include <tessera/geometry/pose2.hpp>
#include <tessera/sim/camera_network.hpp>
#include <tessera/sim/robot.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

namespace camera_network_visit_path_test {

using tessera::Pose2;
using tessera::camera_network::estimateFloorHomography;
using tessera::camera_network::FloorHomography;
using tessera::camera_network::FloorHomographyOptions;
using tessera::camera_network::FloorPixelPair;
using tessera::camera_network::refineVisitPath;
using tessera::camera_network::VisitPathOptions;

const Eigen::Vector2d kMarker(0.1, 0.0);

tessera::sim::EnvironmentCamera camera() {
  tessera::sim::CameraSite site;
  site.id = 1;
  site.position = {4.0, 2.0};
  site.yaw = 0.3;
  site.roll = 0.05;
  site.pitch = -0.04;
  return {site, tessera::sim::CameraIntrinsics{}};
}

/// A visit: the robot drives in, around a loop of 1 m radius under the camera and out at
/// 0.3 m/s, integrated at 50 Hz; sightings at 10 Hz. Truth, odometry (the simulator's noise
/// model) rigidly placed on the truth, and pixels with `pixel_noise` px per axis.
struct Visit {
  std::vector<std::int64_t> stamps;
  std::vector<Pose2> truth, odometry;
  std::vector<Eigen::Vector2d> pixels, true_pixels;
};

Visit drive(const tessera::sim::EnvironmentCamera& cam, double pixel_noise, bool odometry_noise,
            std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> px(0.0, pixel_noise);
  tessera::sim::OdometryNoise noise;
  if (!odometry_noise) noise.sigma_d = noise.sigma_theta = 0;
  Pose2 truth(cam.site().position.x() - 1.5, cam.site().position.y() - 1.0, 0.0);
  tessera::sim::Odometry odom(truth, noise);
  Visit v;
  const double dt = 0.02, speed = 0.3;
  const double loop_s = 2 * M_PI / speed;  // radius 1 m
  for (int step = 0; step <= 2300; ++step) {
    const double t = step * dt;
    if (step % 5 == 0) {
      const auto p = cam.project(truth * kMarker);
      REQUIRE(p);
      v.stamps.push_back(static_cast<std::int64_t>(std::llround(t * 1e9)));
      v.truth.push_back(truth);
      v.odometry.push_back(odom.pose());
      v.true_pixels.push_back(*p);
      v.pixels.push_back(*p + Eigen::Vector2d(px(rng), px(rng)));
    }
    const bool turning = t > 5.0 && t < 5.0 + loop_s;
    const double d = speed * dt, rot = turning ? speed * dt : 0.0;
    truth = tessera::sim::moveBy(truth, d, rot);
    odom.integrate(d, rot, rng);
  }
  // The SLAM places the odometry's path where it best fits (here: on the truth).
  std::vector<Eigen::Vector2d> from, to;
  for (std::size_t k = 0; k < v.truth.size(); ++k) {
    from.push_back(v.odometry[k].translation());
    to.push_back(v.truth[k].translation());
  }
  const Pose2 place = tessera::camera_network::closedFormRigidFit(from, to);
  for (auto& p : v.odometry) p = place * p;
  return v;
}

/// RMS of est - truth after the rigid motion that aligns them best.
double alignedRms(const std::vector<Eigen::Vector2d>& est,
                  const std::vector<Eigen::Vector2d>& truth) {
  const Pose2 align = tessera::camera_network::closedFormRigidFit(est, truth);
  double sse = 0;
  for (std::size_t k = 0; k < est.size(); ++k) sse += (align * est[k] - truth[k]).squaredNorm();
  return std::sqrt(sse / static_cast<double>(est.size()));
}

FloorHomography calibrate(const std::vector<Pose2>& path, const Visit& v) {
  std::vector<FloorPixelPair> pairs;
  for (std::size_t k = 0; k < path.size(); ++k) pairs.push_back({path[k] * kMarker, v.pixels[k]});
  const auto r = estimateFloorHomography(pairs, 640, 480, 1.0, FloorHomographyOptions{});
  REQUIRE(r.homography);
  return *r.homography;
}

/// RMS over the visit of the floor point a calibration gives for the true marker pixels, against
/// the true marker, after the one rigid motion that aligns them best (the calibration's frame
/// is the SLAM's, which these tests do not score).
double localisationRms(const FloorHomography& h, const Visit& v) {
  std::vector<Eigen::Vector2d> est, truth;
  for (std::size_t k = 0; k < v.truth.size(); ++k) {
    const auto f = h.floorPoint(v.true_pixels[k]);
    REQUIRE(f);
    est.push_back(*f);
    truth.push_back(v.truth[k] * kMarker);
  }
  return alignedRms(est, truth);
}

/// The same over a grid across the whole image (where later visits are seen).
/// `aligned` false: in the frame the visit was placed in (on the truth here), so the placement
/// counts too.
double imageRms(const FloorHomography& h, const tessera::sim::EnvironmentCamera& cam,
                const Visit& v, bool aligned = true) {
  // Align as the visit's own points do, then score every pixel of a 16 x 12 grid.
  std::vector<Eigen::Vector2d> est, truth;
  for (std::size_t k = 0; k < v.truth.size(); ++k) {
    est.push_back(*h.floorPoint(v.true_pixels[k]));
    truth.push_back(v.truth[k] * kMarker);
  }
  const Pose2 align =
      aligned ? tessera::camera_network::closedFormRigidFit(est, truth) : Pose2::identity();
  double sse = 0;
  int n = 0;
  for (int i = 0; i < 16; ++i)
    for (int j = 0; j < 12; ++j) {
      const Eigen::Vector2d px(20 + 40 * i, 20 + 40 * j);
      const auto f = h.floorPoint(px);
      const Eigen::Vector2d t = cam.floorPoint(px);
      if (!f) continue;
      sse += (align * *f - t).squaredNorm();
      ++n;
    }
  return std::sqrt(sse / n);
}

double pathRms(const std::vector<Pose2>& path, const Visit& v) {
  std::vector<Eigen::Vector2d> est, truth;
  for (std::size_t k = 0; k < path.size(); ++k) {
    est.push_back(path[k].translation());
    truth.push_back(v.truth[k].translation());
  }
  return alignedRms(est, truth);
}

TEST_CASE(
    "refining a noisy odometry path with the pixels brings path and calibration nearer the "
    "truth",
    "[camera_network][visit_path]") {
  const auto cam = camera();
  double path_before = 0, path_after = 0, loc_before = 0, loc_after = 0;
  double rms_before = 0, rms_after = 0, img_before = 0, img_after = 0;
  double abs_before = 0, abs_after = 0;
  const int runs = 6;
  for (int seed = 1; seed <= runs; ++seed) {
    const Visit v = drive(cam, 1.0, true, static_cast<std::uint64_t>(seed));
    const FloorHomography initial = calibrate(v.odometry, v);
    const auto r =
        refineVisitPath(v.stamps, v.odometry, {}, v.pixels, kMarker, initial, 1.0, 8.0, {});
    REQUIRE(r.refusal.empty());
    REQUIRE(r.poses.size() == v.odometry.size());
    CHECK(r.segments == 23);  // 46 s of increments
    CHECK(r.inliers == static_cast<int>(v.pixels.size()));
    // The corrections stay within what the odometry's noise model allows.
    CHECK(r.prior_chi2 < 4.0 * 2 * r.segments);
    const FloorHomography refined = calibrate(r.poses, v);
    path_before += pathRms(v.odometry, v);
    path_after += pathRms(r.poses, v);
    loc_before += localisationRms(initial, v);
    loc_after += localisationRms(refined, v);
    img_before += imageRms(initial, cam, v);
    img_after += imageRms(refined, cam, v);
    abs_before += imageRms(initial, cam, v, false);
    abs_after += imageRms(refined, cam, v, false);
    rms_before += initial.quality.rms_px;
    rms_after += refined.quality.rms_px;
    // Placed back where the input path was: same centroid.
    Eigen::Vector2d c_in = Eigen::Vector2d::Zero(), c_out = Eigen::Vector2d::Zero();
    for (std::size_t k = 0; k < r.poses.size(); ++k) {
      c_in += v.odometry[k].translation();
      c_out += r.poses[k].translation();
    }
    CHECK((c_in - c_out).norm() / static_cast<double>(r.poses.size()) < 1e-9);
  }
  INFO("path RMS " << path_before / runs << " -> " << path_after / runs << " m, localisation "
                   << loc_before / runs << " -> " << loc_after / runs << " m, reprojection "
                   << rms_before / runs << " -> " << rms_after / runs << " px, image "
                   << img_before / runs << " -> " << img_after / runs << " m, placed "
                   << abs_before / runs << " -> " << abs_after / runs << " m");
  CHECK(path_after < 0.7 * path_before);
  CHECK(loc_after < 0.85 * loc_before);
  // Over the whole image, where later visits are seen, with and without the placement.
  CHECK(img_after < 0.8 * img_before);
  CHECK(abs_after < 0.8 * abs_before);
  CHECK(rms_after < rms_before);
  // Not below what 1 px per axis leaves with the path's few extra parameters.
  CHECK(rms_after / runs > 1.3);
}

TEST_CASE("an exact odometry path stays within the pixels' noise of where it was",
          "[camera_network][visit_path]") {
  // 0.1 px is about 1 mm on the floor here: the corrections fit that noise, nothing more.
  const auto cam = camera();
  const Visit v = drive(cam, 0.1, false, 3);
  const FloorHomography initial = calibrate(v.odometry, v);
  const auto r =
      refineVisitPath(v.stamps, v.odometry, {}, v.pixels, kMarker, initial, 0.1, 8.0, {});
  REQUIRE(r.refusal.empty());
  INFO("reprojection " << r.rms_before_px << " -> " << r.rms_after_px << " px, prior chi2 "
                       << r.prior_chi2);
  CHECK(pathRms(r.poses, v) < 1e-3);
  CHECK(r.max_heading_rad < 5e-3);
  CHECK(r.rms_after_px <= r.rms_before_px);
}

TEST_CASE("the refined path is placed on the anchor's positions", "[camera_network][visit_path]") {
  const auto cam = camera();
  const Visit v = drive(cam, 1.0, true, 2);
  const FloorHomography h = calibrate(v.odometry, v);
  // The SLAM's poses: the truth shifted and turned a little (its placement error).
  const Pose2 off(0.05, -0.03, 0.01);
  std::vector<Pose2> anchor;
  for (const auto& p : v.truth) anchor.push_back(off * p);
  const auto r = refineVisitPath(v.stamps, v.odometry, anchor, v.pixels, kMarker, h, 1.0, 8.0, {});
  REQUIRE(r.refusal.empty());
  Eigen::Vector2d mean_error = Eigen::Vector2d::Zero();
  for (std::size_t k = 0; k < anchor.size(); ++k)
    mean_error += r.poses[k].translation() - anchor[k].translation();
  CHECK(mean_error.norm() / static_cast<double>(anchor.size()) < 1e-9);
  // Its shape is the truth's within a few millimetres, wherever the anchor put it.
  CHECK(pathRms(r.poses, v) < 0.006);
}

TEST_CASE("bad visit paths are refused with the reason", "[camera_network][visit_path]") {
  const auto cam = camera();
  const Visit v = drive(cam, 1.0, true, 5);
  const FloorHomography h = calibrate(v.odometry, v);
  const VisitPathOptions o;
  SECTION("empty and truncated input") {
    CHECK_FALSE(refineVisitPath({}, {}, {}, {}, kMarker, h, 1.0, 8.0, o).refusal.empty());
    auto pixels = v.pixels;
    pixels.pop_back();
    const auto r = refineVisitPath(v.stamps, v.odometry, {}, pixels, kMarker, h, 1.0, 8.0, o);
    CHECK(r.poses.empty());
    CHECK(r.refusal.find("one pixel each") != std::string::npos);
  }
  SECTION("a NaN pose or pixel") {
    auto poses = v.odometry;
    poses[17].theta = std::numeric_limits<double>::quiet_NaN();
    auto r = refineVisitPath(v.stamps, poses, {}, v.pixels, kMarker, h, 1.0, 8.0, o);
    CHECK(r.refusal.find("sighting 17") != std::string::npos);
    auto pixels = v.pixels;
    pixels[3].x() = std::numeric_limits<double>::infinity();
    r = refineVisitPath(v.stamps, v.odometry, {}, pixels, kMarker, h, 1.0, 8.0, o);
    CHECK(r.refusal.find("sighting 3") != std::string::npos);
  }
  SECTION("an anchor of another length") {
    const std::vector<Pose2> anchor(v.odometry.begin(), v.odometry.end() - 1);
    const auto r = refineVisitPath(v.stamps, v.odometry, anchor, v.pixels, kMarker, h, 1.0, 8.0, o);
    CHECK(r.refusal.find("one anchor pose per pose") != std::string::npos);
  }
  SECTION("stamps going back") {
    auto stamps = v.stamps;
    std::swap(stamps[10], stamps[11]);
    const auto r = refineVisitPath(stamps, v.odometry, {}, v.pixels, kMarker, h, 1.0, 8.0, o);
    CHECK(r.refusal.find("back in time at sighting 11") != std::string::npos);
  }
  SECTION("pixels that do not fit the homography") {
    auto pixels = v.pixels;
    for (auto& p : pixels) p += Eigen::Vector2d(50, 0);
    const auto r = refineVisitPath(v.stamps, v.odometry, {}, pixels, kMarker, h, 1.0, 8.0, o);
    CHECK(r.refusal.find("too few inlier pixels") != std::string::npos);
  }
  SECTION("bad options throw, naming the key") {
    VisitPathOptions bad;
    bad.segment_s = 0;
    CHECK_THROWS_WITH(
        refineVisitPath(v.stamps, v.odometry, {}, v.pixels, kMarker, h, 1.0, 8.0, bad),
        Catch::Contains("segment_s"));
    bad = {};
    bad.heading_var_per_rad = std::numeric_limits<double>::quiet_NaN();
    CHECK_THROWS_WITH(
        refineVisitPath(v.stamps, v.odometry, {}, v.pixels, kMarker, h, 1.0, 8.0, bad),
        Catch::Contains("heading_var_per_rad"));
  }
}

}  // namespace camera_network_visit_path_test
