// A synthetic textured wall for the loop-closure tests: random 3D points with random ORB-like
// descriptors, and the LoopView (pixels, descriptors, camera-frame points) a camera at a given
// pose sees of them, with pixel, bit and depth noise. Header-only, test code.
#pragma once

#include <tessera/visual_slam/loop_verifier.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cstdint>
#include <random>
#include <vector>

namespace tessera::test {

namespace vs = tessera::visual_slam;

inline const vs::PinholeCamera kCamera{525, 525, 319.5, 239.5, 640, 480};

// A wall of points at z = 3 m (world), x in [0, 12], y in [-1.2, 1.2], each with its own random
// descriptor.
struct Wall {
  std::vector<Eigen::Vector3d> points;
  std::vector<std::array<std::uint8_t, 32>> descriptors;

  explicit Wall(std::uint32_t seed, int n = 6000) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> ux(0, 12), uy(-1.2, 1.2), uz(-0.3, 0.3);
    std::uniform_int_distribution<int> byte(0, 255);
    for (int i = 0; i < n; ++i) {
      points.emplace_back(ux(rng), uy(rng), 3.0 + uz(rng));
      std::array<std::uint8_t, 32> d{};
      for (auto& b : d) b = static_cast<std::uint8_t>(byte(rng));
      descriptors.push_back(d);
    }
  }
};

// The view of `wall` from camera_to_world: pixels with 0.5 px noise, descriptors with a few
// flipped bits, camera-frame points with point_sigma [m] noise on each axis.
inline vs::LoopView view(const Wall& wall, const Eigen::Isometry3d& camera_to_world,
                         std::uint32_t seed, double point_sigma = 0.005) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> px(0, 0.5), mm(0, point_sigma);
  std::uniform_int_distribution<int> bit(0, 255);
  vs::LoopView v;
  std::vector<std::array<std::uint8_t, 32>> rows;
  const Eigen::Isometry3d camera_from_world = camera_to_world.inverse();
  for (std::size_t i = 0; i < wall.points.size(); ++i) {
    const Eigen::Vector3d p = camera_from_world * wall.points[i];
    if (p.z() < 0.5) continue;
    const Eigen::Vector2d uv = kCamera.project(p) + Eigen::Vector2d(px(rng), px(rng));
    if (!kCamera.inside(uv)) continue;
    v.pixels.push_back(uv);
    v.points.push_back(p + Eigen::Vector3d(mm(rng), mm(rng), mm(rng)));
    auto d = wall.descriptors[i];
    for (int k = 0; k < 6; ++k) {
      const int b = bit(rng);
      d[static_cast<std::size_t>(b / 8)] ^= static_cast<std::uint8_t>(1u << (b % 8));
    }
    rows.push_back(d);
  }
  v.descriptors = cv::Mat(static_cast<int>(rows.size()), 32, CV_8UC1);
  for (int r = 0; r < v.descriptors.rows; ++r)
    std::copy(rows[static_cast<std::size_t>(r)].begin(), rows[static_cast<std::size_t>(r)].end(),
              v.descriptors.ptr<std::uint8_t>(r));
  return v;
}

inline Eigen::Isometry3d cameraAt(double x, double yaw = 0, double y = 0) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, 0);
  return T;
}

}  // namespace tessera::test
