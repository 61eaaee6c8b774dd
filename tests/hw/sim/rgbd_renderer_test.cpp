// The simulated RGB-D camera: depth against analytic distances (walls, a table top), a table top
// that the camera sees while the planar laser passes under it, ORB features on the procedural
// textures, the visual_slam Tracker on a short rendered route (ATE), render time, bad options.
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/sim/ray_caster.hpp>
#include <tessera/sim/rgbd_renderer.hpp>
#include <tessera/visual_slam/feature_extractor.hpp>
#include <tessera/visual_slam/tracker.hpp>

#include <catch2/catch.hpp>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

using tessera::Pose2;
using tessera::sim::RgbdCameraConfig;
using tessera::sim::RgbdImage;
using tessera::sim::RgbdRenderer;
using tessera::sim::World;
namespace vs = tessera::visual_slam;

namespace {

// A noise-free camera whose centre pixel (320, 240) looks exactly along the optical axis.
RgbdCameraConfig exactCamera(double height, double pitch) {
  RgbdCameraConfig c;
  c.cx = 320;
  c.cy = 240;
  c.depth_noise = 0;
  c.image_noise = 0;
  c.range_max = 10;
  c.mount = {0, 0, height, 0, pitch, 0};
  return c;
}

float depthAt(const RgbdImage& im, int u, int v) {
  return im.depth[static_cast<std::size_t>(v) * im.width + u];
}

vs::PinholeCamera pinhole(const RgbdCameraConfig& c) {
  return {c.fx, c.fy, c.cx, c.cy, c.width, c.height};
}

// The frame as the visual front end takes it: colour as is, depth in millimetres (16UC1).
struct FrameBuffers {
  cv::Mat color, depth_mm;
  vs::RgbdFrame frame(double stamp) const { return {color, depth_mm, 1000.0, stamp}; }
};
FrameBuffers toFrame(const RgbdImage& im) {
  FrameBuffers f;
  f.color = cv::Mat(im.height, im.width, CV_8UC3, const_cast<std::uint8_t*>(im.rgb.data())).clone();
  f.depth_mm = cv::Mat(im.height, im.width, CV_16UC1);
  for (int v = 0; v < im.height; ++v)
    for (int u = 0; u < im.width; ++u)
      f.depth_mm.at<std::uint16_t>(v, u) =
          static_cast<std::uint16_t>(std::lround(depthAt(im, u, v) * 1000.0f));
  return f;
}

}  // namespace

TEST_CASE("rgbd renderer: depth equals the analytic distance to a wall and a table top",
          "[sim][rgbd]") {
  // Box world 8 m x 6 m with one-cell walls: free inside x in [0.05, 7.95], y in [0.05, 5.95].
  World world = World::box(8, 6, 0.05);
  world.addFurniture(tessera::sim::makeTable(4, 2.5, 5, 3.5));  // top z in [0.71, 0.75]
  const Pose2 base{2, 3, 0};

  SECTION("wall straight ahead, floor and ceiling") {
    const RgbdRenderer r(world, 2.5, exactCamera(1.6, 0));
    RgbdImage im;
    r.render(r.cameraPose(base), 1, im);
    // Centre ray: over the table (z 1.6 > 0.75) to the east wall at x = 7.95.
    CHECK(depthAt(im, 320, 240) == Approx(5.95).margin(1e-4));
    // castRay along +x from the camera, and straight down / up.
    const Eigen::Vector3d o(2, 3, 1.6);
    CHECK(r.castRay(o, {1, 0, 0}) == Approx(5.95).margin(1e-9));
    CHECK(r.castRay(o, {0, 0, -1}) == Approx(1.6).margin(1e-9));
    CHECK(r.castRay(o, {0, 0, 2}) == Approx(0.45).margin(1e-9));  // t for |dir| = 2
    CHECK(r.castRay(o, {0, -1, 0}) == Approx(2.95).margin(1e-9));
    // Depth is z in the camera, not the ray length: a pixel off-centre on the same wall plane
    // has the same depth (within a cell's rasterisation, none here: the wall is a plane).
    CHECK(depthAt(im, 420, 240) == Approx(5.95).margin(1e-4));
  }

  SECTION("table top, and the planar laser passes under it") {
    // Pitched down so the centre ray meets the table top at (4.5, 3, 0.75).
    const double pitch = std::atan2(1.0 - 0.75, 2.5);
    const RgbdRenderer r(world, 2.5, exactCamera(1.0, pitch));
    RgbdImage im;
    r.render(r.cameraPose(base), 1, im);
    CHECK(depthAt(im, 320, 240) == Approx(std::hypot(2.5, 0.25)).margin(1e-4));

    tessera::sim::LaserConfig laser;
    laser.range_noise = 0;
    const tessera::sim::LaserModel model(world, laser);
    std::mt19937_64 rng(1);
    const auto ranges = model.scan(base, rng);
    // The beam straight ahead (the middle of 181 over 180 degrees) reaches the wall behind the
    // table: 5.95 m, not the table's edge at 2 m.
    CHECK(ranges[90] == Approx(5.95).margin(1e-6));
  }

  SECTION("range limits give no reading (0)") {
    auto c = exactCamera(1.6, 0);
    c.range_max = 5.0;
    const RgbdRenderer r(world, 2.5, c);
    RgbdImage im;
    r.render(r.cameraPose(base), 1, im);
    CHECK(depthAt(im, 320, 240) == 0.0f);
    CHECK(im.rgb[(240 * 640 + 320) * 3] + im.rgb[(240 * 640 + 320) * 3 + 1] > 0);  // colour stays
  }
}

TEST_CASE("rgbd renderer: depth noise grows with z squared and repeats per seed", "[sim][rgbd]") {
  const World world = World::box(8, 6, 0.05);
  auto c = exactCamera(1.6, 0);
  c.depth_noise = 0.01;
  const RgbdRenderer r(world, 2.5, c);
  RgbdImage a, b;
  r.render(r.cameraPose({2, 3, 0}), 7, a);
  r.render(r.cameraPose({2, 3, 0}), 7, b);
  CHECK(a.depth == b.depth);
  CHECK(a.rgb == b.rgb);
  // The centre row on the east wall: every depth is 5.95 + noise of std 0.01 * 5.95^2 = 0.354.
  double sum = 0, sum2 = 0;
  int n = 0;
  for (int u = 220; u < 420; ++u) {
    const double e = depthAt(a, u, 240) - 5.95;
    if (depthAt(a, u, 240) == 0) continue;
    sum += e;
    sum2 += e * e;
    ++n;
  }
  REQUIRE(n > 150);
  CHECK(std::sqrt(sum2 / n - (sum / n) * (sum / n)) == Approx(0.354).epsilon(0.2));
}

TEST_CASE("rgbd renderer: the office has tables the camera sees, and textures give ORB features",
          "[sim][rgbd]") {
  const World office = World::builtinOffice();
  REQUIRE(office.furniture().size() >= 20);
  const RgbdCameraConfig config;  // defaults: 640 x 480, noise on
  const RgbdRenderer r(office, 2.5, config);
  RgbdImage im;
  // The west corridor, looking north along it.
  const Eigen::Isometry3d pose = r.cameraPose({7.5, 12.0, std::numbers::pi / 2});
  r.render(pose, 1, im);  // warm up (TBB threads)

  std::vector<double> ms;
  for (int i = 0; i < 5; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    r.render(pose, static_cast<std::uint64_t>(i), im);
    ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ms.begin(), ms.end());
  std::printf("rgbd render 640x480 (office corridor): median %.1f ms, min %.1f ms over 5\n", ms[2],
              ms[0]);

  const vs::FeatureExtractor extractor({}, pinhole(config));
  const FrameBuffers f = toFrame(im);
  cv::Mat gray;
  cv::cvtColor(f.color, gray, cv::COLOR_RGB2GRAY);
  const vs::Features features = extractor.extract(gray, f.depth_mm, 1000.0);
  int full = 0;
  for (int count : features.per_cell) full += count >= features.cell_budget / 2 ? 1 : 0;
  std::printf(
      "rgbd render: %zu ORB features (%zu with depth), %d of %zu cells at least half full\n",
      features.size(), features.with_depth, full, features.per_cell.size());
  CHECK(full >= static_cast<int>(features.per_cell.size() * 9 / 10));
  CHECK(features.with_depth > features.size() / 2);
}

TEST_CASE("rgbd renderer: the visual_slam tracker follows a short rendered route",
          "[sim][rgbd][slow]") {
  const World office = World::builtinOffice();
  const RgbdCameraConfig config;
  const RgbdRenderer r(office, 2.5, config);
  vs::Tracker tracker({}, pinhole(config));

  // 60 frames at 15 Hz (4 s) in the bottom middle room: 0.4 m/s west past the table, turning.
  std::vector<tessera::mapping::TumPose> estimate, reference;
  RgbdImage im;
  int lost = 0;
  for (int k = 0; k < 60; ++k) {
    const double t = k / 15.0;
    const Pose2 base{23.5 - 0.4 * t, 3.0 + 0.1 * std::sin(t), std::numbers::pi - 0.25 * t};
    const Eigen::Isometry3d truth = r.cameraPose(base);
    r.render(truth, static_cast<std::uint64_t>(k), im);
    const FrameBuffers f = toFrame(im);
    const auto result = tracker.track(f.frame(t));
    const auto stamp = static_cast<std::int64_t>(std::llround(t * 1e9));
    tessera::mapping::TumPose ref;
    ref.stamp_ns = stamp;
    ref.position = truth.translation();
    ref.orientation = Eigen::Quaterniond(truth.rotation());
    reference.push_back(ref);
    if (!result.pose_valid) {
      ++lost;
      continue;
    }
    tessera::mapping::TumPose est = ref;
    est.position = result.camera_to_world.translation();
    est.orientation = Eigen::Quaterniond(result.camera_to_world.rotation());
    estimate.push_back(est);
  }
  const auto ate = tessera::evaluation::computeAte(estimate, reference);
  std::printf("rgbd sim tracker: 60 frames, %d lost, %zu keyframes, ATE RMSE %.4f m (max %.4f)\n",
              lost, tracker.stats().keyframes, ate.translation.rmse, ate.translation.max);
  CHECK(lost == 0);
  CHECK(ate.translation.rmse < 0.03);
}

TEST_CASE("rgbd renderer: bad options name the key", "[sim][rgbd]") {
  const World world = World::box(4, 4, 0.05);
  auto fails = [&](RgbdCameraConfig c, const std::string& key, double wall_height = 2.5) {
    INFO(key);
    try {
      RgbdRenderer r(world, wall_height, c);
      FAIL("no error");
    } catch (const std::invalid_argument& e) {
      CHECK_THAT(e.what(), Catch::Contains(key));
    }
  };
  RgbdCameraConfig c;
  c.width = 0;
  fails(c, "width");
  c = {};
  c.height = -3;
  fails(c, "height");
  c = {};
  c.mount.x = std::numeric_limits<double>::quiet_NaN();
  fails(c, "mount.x");
  c = {};
  c.mount.yaw = std::numeric_limits<double>::infinity();
  fails(c, "mount.yaw");
  c = {};
  c.depth_noise = -0.1;
  fails(c, "depth_noise");
  c = {};
  c.image_noise = std::numeric_limits<double>::quiet_NaN();
  fails(c, "image_noise");
  c = {};
  c.fx = 0;
  fails(c, "fx");
  c = {};
  c.range_max = 0.1;
  fails(c, "range_max");
  c = {};
  c.mount.z = 3.0;  // above the ceiling
  fails(c, "mount.z");
  fails({}, "wall_height", 0.0);
  fails({}, "wall_height", std::numeric_limits<double>::quiet_NaN());
}

TEST_CASE("rgbd renderer: walls found by direction gaps equal the per-ray grid traversal",
          "[sim][rgbd]") {
  // The renderer looks walls up per gap between wall corners (rgbd_renderer.hpp); castRay
  // traverses the grid for each ray. Noise-free depth must agree on every sampled pixel, in
  // corridors (long grazing rays), at doors and round pillars, and with the camera rolled.
  const World office = World::builtinOffice();
  auto c = exactCamera(1.0, 0.15);
  c.range_min = 0;
  c.range_max = 100;
  const double pi = std::numbers::pi;
  for (const auto& [base, roll] : {std::pair{Pose2{7.5, 12.0, pi / 2}, 0.0},
                                   {Pose2{14.6, 15.0, 0.02}, 0.0},
                                   {Pose2{32.5, 8.0, 2.0}, 0.3},
                                   {Pose2{23.0, 14.2, 1.3}, 0.0}}) {
    c.mount.roll = roll;
    const RgbdRenderer r(office, 2.5, c);
    const Eigen::Isometry3d pose = r.cameraPose(base);
    RgbdImage im;
    r.render(pose, 1, im);
    int checked = 0, differ = 0;
    for (int v = 0; v < c.height; v += 3)
      for (int u = 0; u < c.width; u += 3) {
        const Eigen::Vector3d d =
            pose.linear() * Eigen::Vector3d((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.0);
        const double t = r.castRay(pose.translation(), d);
        ++checked;
        differ += std::abs(depthAt(im, u, v) - static_cast<float>(t)) > 1e-5f * t ? 1 : 0;
      }
    INFO("pose " << base.x << " " << base.y << " " << base.theta << ", roll " << roll);
    CHECK(checked > 30000);
    CHECK(differ == 0);
  }
}

// Hidden: per-view render times over office views (corridors are the slowest), for before/after
// comparisons: build/bin/tessera_tests "[.rgbd_render_bench]". With TESSERA_RENDER_DUMP=DIR it
// writes each view's colour and depth there, with TESSERA_RENDER_COMPARE=DIR it compares them.
TEST_CASE("rgbd renderer: render time per office view", "[.rgbd_render_bench]") {
  const World office = World::builtinOffice();
  const RgbdCameraConfig config;
  const RgbdRenderer r(office, 2.5, config);
  const double pi = std::numbers::pi;
  const std::vector<std::pair<const char*, Pose2>> views = {
      {"west corridor north", {7.5, 12.0, pi / 2}},
      {"bottom corridor east", {7.5, 7.5, 0}},
      {"cross corridor east", {14.6, 15.0, 0}},
      {"east corridor north", {32.5, 8.0, pi / 2}},
      {"top corridor west", {32.5, 22.5, pi}},
      {"south room", {21.0, 4.0, -pi / 2}},
      {"room table", {23.5, 3.0, pi}},
      {"east room", {37.0, 10.5, 0.3}}};
  RgbdImage im;
  const char* dump = std::getenv("TESSERA_RENDER_DUMP");
  const char* compare = std::getenv("TESSERA_RENDER_COMPARE");
  double total = 0;
  for (std::size_t k = 0; k < views.size(); ++k) {
    const Eigen::Isometry3d pose = r.cameraPose(views[k].second);
    r.render(pose, 1, im);  // warm up
    std::vector<double> ms;
    for (int i = 0; i < 7; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      r.render(pose, 1, im);
      ms.push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    }
    std::sort(ms.begin(), ms.end());
    total += ms[3];
    std::printf("%-22s median %6.1f ms (min %6.1f)\n", views[k].first, ms[3], ms[0]);
    const std::string base = std::string("/view") + std::to_string(k);
    if (dump) {
      std::FILE* f = std::fopen((dump + base).c_str(), "wb");
      REQUIRE(f);
      std::fwrite(im.rgb.data(), 1, im.rgb.size(), f);
      std::fwrite(im.depth.data(), sizeof(float), im.depth.size(), f);
      std::fclose(f);
    }
    if (compare) {
      std::FILE* f = std::fopen((compare + base).c_str(), "rb");
      REQUIRE(f);
      std::vector<std::uint8_t> rgb(im.rgb.size());
      std::vector<float> depth(im.depth.size());
      REQUIRE(std::fread(rgb.data(), 1, rgb.size(), f) == rgb.size());
      REQUIRE(std::fread(depth.data(), sizeof(float), depth.size(), f) == depth.size());
      std::fclose(f);
      std::size_t rgb_diff = 0, depth_diff = 0;
      double depth_max = 0;
      for (std::size_t i = 0; i < rgb.size(); ++i) rgb_diff += rgb[i] != im.rgb[i] ? 1 : 0;
      for (std::size_t i = 0; i < depth.size(); ++i) {
        const double e = std::abs(static_cast<double>(depth[i]) - im.depth[i]);
        depth_diff += e > 0 ? 1 : 0;
        depth_max = std::max(depth_max, e);
      }
      std::printf("  vs reference: %zu colour bytes and %zu depths differ (max %.3g m)\n", rgb_diff,
                  depth_diff, depth_max);
    }
  }
  std::printf("sum of medians %.1f ms\n", total);
}
