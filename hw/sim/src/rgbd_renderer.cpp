// RgbdRenderer: per-pixel ray casting over the extruded wall grid, floor, ceiling and furniture
// boxes, with procedural textures and depth / colour noise (see rgbd_renderer.hpp).
#include <tessera/sim/rgbd_renderer.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>

namespace tessera::sim {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::uint64_t mix(std::uint64_t x) {  // splitmix64 finaliser
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}
std::uint64_t hash3(std::uint64_t a, std::int64_t b, std::int64_t c) {
  return mix(mix(mix(a) ^ static_cast<std::uint64_t>(b)) ^ static_cast<std::uint64_t>(c));
}
double unit(std::uint64_t h) {  // [0, 1)
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

// A small, fast generator for per-row noise streams (a UniformRandomBitGenerator).
struct SplitMix {
  using result_type = std::uint64_t;
  std::uint64_t state;
  static constexpr result_type min() { return 0; }
  static constexpr result_type max() { return ~result_type{0}; }
  result_type operator()() { return mix(state += 0x9e3779b97f4a7c15ull); }
};

// Surface kinds, so that equal coordinates on different surfaces get different patterns.
enum Surface : std::uint64_t { kFloor = 1, kCeiling = 2, kWallX = 3, kWallY = 4, kBox = 5 };

// The texture: grey squares of `coarse` and coarse/3 metres (a mosaic with corners at many
// scales), tinted by a colour of the face; `shade` darkens faces by orientation.
void texture(std::uint64_t key, double s, double t, double coarse, double shade,
             std::uint8_t* rgb) {
  const double fine = coarse / 3;
  const double g1 = unit(hash3(key, static_cast<std::int64_t>(std::floor(s / coarse)),
                               static_cast<std::int64_t>(std::floor(t / coarse))));
  const double g2 = unit(hash3(key ^ 0x5bd1e995u, static_cast<std::int64_t>(std::floor(s / fine)),
                               static_cast<std::int64_t>(std::floor(t / fine))));
  const double grey = (0.25 + 0.5 * g1 + 0.25 * g2) * shade;
  const std::uint64_t tint = mix(key);
  for (int c = 0; c < 3; ++c) {
    const double tone = 0.65 + 0.35 * unit(mix(tint + static_cast<std::uint64_t>(c)));
    rgb[c] = static_cast<std::uint8_t>(std::clamp(255.0 * grey * tone, 0.0, 255.0));
  }
}

}  // namespace

struct RgbdRenderer::Hit {
  double t = kInf;
  std::uint64_t key = 0;  // surface identity for its texture
  int axis = 2;           // axis of the face normal (0 x, 1 y, 2 z)
};

Eigen::Isometry3d Mount3D::bodyToBase() const {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translate(Eigen::Vector3d(x, y, z));
  T.rotate(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
           Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
           Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()));
  return T;
}

ConfigCheck RgbdCameraConfig::check() const {
  ConfigCheck c;
  c.require(width > 0, "width", "must be > 0", width)
      .require(height > 0, "height", "must be > 0", height)
      .require(static_cast<double>(width) * height <= 4096.0 * 4096.0, "width",
               "times height must be at most 4096^2", width)
      .positive("fx", fx)
      .positive("fy", fy)
      .require(std::isfinite(cx), "cx", "must be finite", cx)
      .require(std::isfinite(cy), "cy", "must be finite", cy)
      .nonNegative("range_min", range_min)
      .require(std::isfinite(range_max) && range_max > range_min, "range_max",
               "must be finite and > range_min", range_max)
      .nonNegative("depth_noise", depth_noise)
      .nonNegative("image_noise", image_noise)
      .require(std::isfinite(mount.x), "mount.x", "must be finite", mount.x)
      .require(std::isfinite(mount.y), "mount.y", "must be finite", mount.y)
      .require(std::isfinite(mount.z), "mount.z", "must be finite", mount.z)
      .require(std::isfinite(mount.roll), "mount.roll", "must be finite", mount.roll)
      .require(std::isfinite(mount.pitch), "mount.pitch", "must be finite", mount.pitch)
      .require(std::isfinite(mount.yaw), "mount.yaw", "must be finite", mount.yaw);
  return c;
}

RgbdRenderer::RgbdRenderer(const World& world, double wall_height, const RgbdCameraConfig& config)
    : world_(&world), wall_height_(wall_height), config_(config) {
  config_.check().throwIfBad("rgbd camera");
  ConfigCheck().positive("wall_height", wall_height).throwIfBad("rgbd camera");
  ConfigCheck()
      .require(config_.mount.z > 0 && config_.mount.z < wall_height, "mount.z",
               "must be between the floor and the ceiling (wall_height)", config_.mount.z)
      .throwIfBad("rgbd camera");
}

Eigen::Isometry3d RgbdRenderer::cameraPose(const Pose2& base) const {
  Eigen::Isometry3d world_base = Eigen::Isometry3d::Identity();
  world_base.translate(Eigen::Vector3d(base.x, base.y, 0));
  world_base.rotate(Eigen::AngleAxisd(base.theta, Eigen::Vector3d::UnitZ()));
  // Optical axes in the body frame: x right = -y, y down = -z, z forward = +x.
  Eigen::Matrix3d body_optical;
  body_optical << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  Eigen::Isometry3d optical = Eigen::Isometry3d::Identity();
  optical.linear() = body_optical;
  return world_base * config_.mount.bodyToBase() * optical;
}

RgbdRenderer::Hit RgbdRenderer::trace(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                                      const std::vector<int>& boxes) const {
  Hit hit;
  // Floor and ceiling bound every ray that is not parallel to them.
  if (d.z() < 0) {
    hit.t = -o.z() / d.z();
    hit.key = kFloor;
  } else if (d.z() > 0) {
    hit.t = (wall_height_ - o.z()) / d.z();
    hit.key = kCeiling;
  }

  // Furniture: slab tests.
  const auto& furniture = world_->furniture();
  for (int i : boxes) {
    const FurnitureBox& b = furniture[static_cast<std::size_t>(i)];
    double t0 = 0, t1 = hit.t;
    int axis = -1;
    bool miss = false;
    for (int a = 0; a < 3 && !miss; ++a) {
      if (d[a] == 0) {
        miss = o[a] < b.lo[a] || o[a] > b.hi[a];
        continue;
      }
      double ta = (b.lo[a] - o[a]) / d[a], tb = (b.hi[a] - o[a]) / d[a];
      if (ta > tb) std::swap(ta, tb);
      if (ta > t0) {
        t0 = ta;
        axis = a;
      }
      t1 = std::min(t1, tb);
      miss = t0 > t1;
    }
    if (!miss && axis >= 0 && t0 < hit.t) {
      hit.t = t0;
      hit.axis = axis;
      hit.key = mix(kBox + 16 * static_cast<std::uint64_t>(i)) + static_cast<std::uint64_t>(axis);
    }
  }
  if (hit.key == kFloor || hit.key == kCeiling) hit.axis = 2;

  // Walls: exact traversal of the grid cells the ray's floor projection crosses, up to the
  // nearest hit so far.
  const World& w = *world_;
  const double res = w.resolution();
  int col = static_cast<int>(std::floor(o.x() / res)),
      row = static_cast<int>(std::floor(o.y() / res));
  if (w.wall(col, row)) return {0.0, kWallX, 0};
  const int step_c = d.x() > 0 ? 1 : -1, step_r = d.y() > 0 ? 1 : -1;
  const double dtx = d.x() != 0 ? res / std::abs(d.x()) : kInf;
  const double dty = d.y() != 0 ? res / std::abs(d.y()) : kInf;
  double tx = d.x() != 0 ? ((col + (step_c > 0 ? 1 : 0)) * res - o.x()) / d.x() : kInf;
  double ty = d.y() != 0 ? ((row + (step_r > 0 ? 1 : 0)) * res - o.y()) / d.y() : kInf;
  while (true) {
    double t_enter;
    int axis;
    if (tx < ty) {
      t_enter = tx;
      tx += dtx;
      col += step_c;
      axis = 0;
    } else {
      t_enter = ty;
      ty += dty;
      row += step_r;
      axis = 1;
    }
    if (t_enter >= hit.t) break;
    if (!w.inside(col, row)) {
      // Outside the map nothing stands, and a ray that has left never comes back.
      if ((col < 0 && step_c < 0) || (col >= w.width() && step_c > 0) || (row < 0 && step_r < 0) ||
          (row >= w.height() && step_r > 0))
        break;
      continue;
    }
    if (w.wall(col, row)) {
      // The face is the boundary line crossed: its index along the axis and the side seen.
      const std::int64_t line = axis == 0 ? col + (step_c < 0 ? 1 : 0) : row + (step_r < 0 ? 1 : 0);
      const int side = axis == 0 ? step_c : step_r;
      hit.t = t_enter;
      hit.axis = axis;
      hit.key = hash3(axis == 0 ? kWallX : kWallY, line, side);
      break;
    }
  }
  return hit;
}

double RgbdRenderer::castRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir) const {
  std::vector<int> all(world_->furniture().size());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  return trace(origin, dir, all).t;
}

void RgbdRenderer::render(const Eigen::Isometry3d& camera_to_world, std::uint64_t noise_seed,
                          RgbdImage& out) const {
  const RgbdCameraConfig& c = config_;
  out.width = c.width;
  out.height = c.height;
  const auto pixels = static_cast<std::size_t>(c.width) * static_cast<std::size_t>(c.height);
  out.rgb.resize(pixels * 3);
  out.depth.resize(pixels);

  const Eigen::Vector3d o = camera_to_world.translation();
  const Eigen::Matrix3d R = camera_to_world.linear();

  // Boxes that can be in view: not wholly behind the camera (every corner at z <= 0 in it).
  std::vector<int> boxes;
  const auto& furniture = world_->furniture();
  for (std::size_t i = 0; i < furniture.size(); ++i) {
    const FurnitureBox& b = furniture[i];
    bool in_front = false;
    for (int k = 0; k < 8 && !in_front; ++k) {
      const Eigen::Vector3d corner((k & 1) ? b.hi.x() : b.lo.x(), (k & 2) ? b.hi.y() : b.lo.y(),
                                   (k & 4) ? b.hi.z() : b.lo.z());
      in_front = R.col(2).dot(corner - o) > 0;
    }
    if (in_front) boxes.push_back(static_cast<int>(i));
  }

  tbb::parallel_for(tbb::blocked_range<int>(0, c.height), [&](const tbb::blocked_range<int>& rows) {
    std::normal_distribution<float> normal(0.0f, 1.0f);
    for (int v = rows.begin(); v != rows.end(); ++v) {
      SplitMix rng{hash3(noise_seed, v, 0x726f77)};  // "row": one stream per row
      const Eigen::Vector3d row_dir = R.col(1) * ((v - c.cy) / c.fy) + R.col(2);
      for (int u = 0; u < c.width; ++u) {
        // Optical z of the direction is 1, so t is the depth z.
        const Eigen::Vector3d d = row_dir + R.col(0) * ((u - c.cx) / c.fx);
        const Hit hit = trace(o, d, boxes);
        const std::size_t i = static_cast<std::size_t>(v) * c.width + u;
        std::uint8_t* px = &out.rgb[i * 3];
        if (!std::isfinite(hit.t)) {
          px[0] = px[1] = px[2] = 0;
          out.depth[i] = 0;
          continue;
        }
        const Eigen::Vector3d p = o + hit.t * d;
        switch (hit.axis) {
          case 0:
            texture(hit.key, p.y(), p.z(), 0.3, 0.95, px);
            break;
          case 1:
            texture(hit.key, p.x(), p.z(), 0.3, 0.8, px);
            break;
          default:
            texture(hit.key, p.x(), p.y(), hit.key == kFloor ? 0.45 : 0.3,
                    hit.key == kCeiling ? 0.7 : 0.9, px);
            break;
        }
        double z = hit.t;
        if (c.depth_noise > 0) z += c.depth_noise * z * z * normal(rng);
        out.depth[i] = (z >= c.range_min && z <= c.range_max) ? static_cast<float>(z) : 0.0f;
        if (c.image_noise > 0)
          for (int k = 0; k < 3; ++k)
            px[k] = static_cast<std::uint8_t>(
                std::clamp(std::lround(px[k] + c.image_noise * normal(rng)), long{0}, long{255}));
      }
    }
  });
}

}  // namespace tessera::sim
