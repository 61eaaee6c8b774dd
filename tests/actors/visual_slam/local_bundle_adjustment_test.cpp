// Local bundle adjustment on synthetic keyframes: the perturbed poses of the newest keyframes and
// their shared points return to the truth, older keyframes stay fixed, and the options are
// checked.
#include <tessera/visual_slam/local_bundle_adjustment.hpp>
#include <tessera/visual_slam/tracker.hpp>

#include <catch2/catch.hpp>

#include <limits>
#include <random>
#include <vector>

namespace vs = tessera::visual_slam;

namespace {

// Six keyframes stepping 10 cm along x and turning slightly, all seeing 150 points 1.5-4 m away
// (ids shared, depth measured exactly); the last `perturbed` get their pose and points moved.
std::vector<vs::Keyframe> scene(const vs::PinholeCamera& cam, int perturbed,
                                std::vector<Eigen::Isometry3d>& truth) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> x(-1.5, 1.5), y(-1.0, 1.0), z(1.5, 4.0), n(-1, 1);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 150; ++i) points.emplace_back(x(rng), y(rng), z(rng));
  std::vector<vs::Keyframe> kfs;
  truth.clear();
  for (int k = 0; k < 6; ++k) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::AngleAxisd(0.02 * k, Eigen::Vector3d::UnitY()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(0.1 * k, 0, 0);
    truth.push_back(T);
    const bool moved = k >= 6 - perturbed;
    vs::Keyframe kf;
    kf.id = static_cast<std::size_t>(k);
    kf.camera_to_world = T;
    if (moved) {
      kf.camera_to_world.translation() += Eigen::Vector3d(0.02, -0.01, 0.015);
      kf.camera_to_world.linear() =
          kf.camera_to_world.linear() *
          Eigen::AngleAxisd(0.01, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
    }
    for (std::size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3d c = T.inverse() * points[i];
      const Eigen::Vector2d uv = cam.project(c);
      if (c.z() <= 0.1 || !cam.inside(uv)) continue;
      kf.keypoints.emplace_back(static_cast<float>(uv.x()), static_cast<float>(uv.y()), 8.f);
      kf.points_camera.push_back(c);
      // Points first seen by a perturbed keyframe carry its error, as tracking would leave them.
      kf.points_world.push_back(
          points[i] + (moved ? Eigen::Vector3d(0.01 * n(rng), 0.01 * n(rng), 0.01 * n(rng))
                             : Eigen::Vector3d::Zero()));
      kf.point_ids.push_back(static_cast<std::int64_t>(i));
    }
    kfs.push_back(std::move(kf));
  }
  return kfs;
}

}  // namespace

TEST_CASE("local bundle adjustment pulls the newest keyframes back to the truth", "[visual_slam]") {
  const vs::PinholeCamera cam{525, 525, 319.5, 239.5, 640, 480};
  std::vector<Eigen::Isometry3d> truth;
  auto kfs = scene(cam, 2, truth);
  vs::LocalBundleAdjustmentOptions o;
  o.keyframes = 3;
  o.fixed_keyframes = 3;
  o.iterations = 10;
  const auto before = kfs;
  const auto stats = vs::adjustLocalWindow(kfs, cam, o);
  REQUIRE(stats.ran);
  CHECK(stats.adjusted_keyframes == 3);
  CHECK(stats.fixed_keyframes == 3);
  CHECK(stats.points > 100);
  CHECK(stats.final_cost < 0.01 * stats.initial_cost);
  for (int k = 0; k < 6; ++k) {
    const auto& T = kfs[static_cast<std::size_t>(k)].camera_to_world;
    INFO("keyframe " << k);
    CHECK((T.translation() - truth[static_cast<std::size_t>(k)].translation()).norm() < 1e-3);
    CHECK(
        Eigen::AngleAxisd(T.rotation().transpose() * truth[static_cast<std::size_t>(k)].rotation())
            .angle() < 1e-3);
    if (k < 3) CHECK(T.isApprox(before[static_cast<std::size_t>(k)].camera_to_world));
  }
  // Every copy of a point moved together.
  for (std::size_t j = 0; j < kfs[5].point_ids.size(); ++j)
    for (std::size_t i = 0; i < kfs[4].point_ids.size(); ++i)
      if (kfs[4].point_ids[i] == kfs[5].point_ids[j])
        CHECK(kfs[4].points_world[i] == kfs[5].points_world[j]);
}

TEST_CASE("local bundle adjustment: off, too few keyframes, no shared points, bad options",
          "[visual_slam]") {
  const vs::PinholeCamera cam{525, 525, 319.5, 239.5, 640, 480};
  std::vector<Eigen::Isometry3d> truth;
  auto kfs = scene(cam, 1, truth);
  vs::LocalBundleAdjustmentOptions o;
  CHECK_FALSE(vs::adjustLocalWindow(kfs, cam, o).ran);  // off by default
  o.keyframes = 3;
  std::vector<vs::Keyframe> one(kfs.begin(), kfs.begin() + 1);
  CHECK_FALSE(vs::adjustLocalWindow(one, cam, o).ran);
  std::vector<vs::Keyframe> none;
  CHECK_FALSE(vs::adjustLocalWindow(none, cam, o).ran);
  auto lonely = kfs;
  for (auto& k : lonely)
    for (std::size_t j = 0; j < k.point_ids.size(); ++j)
      k.point_ids[j] = static_cast<std::int64_t>(1000 * k.id + j);  // nothing shared
  CHECK_FALSE(vs::adjustLocalWindow(lonely, cam, o).ran);
  // Without older keyframes the oldest of the window holds the gauge.
  std::vector<vs::Keyframe> two(kfs.end() - 2, kfs.end());
  const auto first = two[0].camera_to_world;
  const auto s = vs::adjustLocalWindow(two, cam, o);
  CHECK(s.ran);
  CHECK(s.fixed_keyframes == 1);
  CHECK(two[0].camera_to_world.isApprox(first));
  for (auto bad : {-1, 0}) {
    vs::LocalBundleAdjustmentOptions b;
    b.iterations = bad;
    CHECK_THROWS_AS(b.validate(), std::invalid_argument);
  }
  vs::LocalBundleAdjustmentOptions b;
  b.keyframes = -1;
  CHECK_THROWS_AS(b.validate(), std::invalid_argument);
  b = {};
  b.huber_delta = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_AS(b.validate(), std::invalid_argument);
  vs::TrackerOptions t;
  t.local_ba.fixed_keyframes = -2;
  CHECK_THROWS_AS(t.validate(), std::invalid_argument);
}
