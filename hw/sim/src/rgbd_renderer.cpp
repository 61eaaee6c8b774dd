// RgbdRenderer: per-pixel ray casting over the extruded wall grid, floor, ceiling and furniture
// boxes, with procedural textures and depth / colour noise (see rgbd_renderer.hpp).
#include <tessera/sim/rgbd_renderer.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
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

// Per-row noise stream: a counter through the splitmix finaliser. gaussian() sums four 16-bit
// uniforms (Irwin-Hall, rescaled to unit variance): close enough to a normal for sensor noise,
// bounded at +-3.46 sigma, and several times cheaper than std::normal_distribution.
struct NoiseStream {
  std::uint64_t state;
  float gaussian() {
    const std::uint64_t h = mix(state += 0x9e3779b97f4a7c15ull);
    const auto sum =
        static_cast<float>((h & 0xffff) + ((h >> 16) & 0xffff) + ((h >> 32) & 0xffff) + (h >> 48));
    constexpr float kScale = 1.7320508f / 65536.0f;  // sqrt(12 / 4) per unit of the sum
    return (sum - 2.0f * 65535.0f) * kScale;
  }
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
  double plane = 0;       // walls: the face's x (axis 0) or y (axis 1) [m]
};

// The wall faces seen from one camera position, by horizontal direction. A direction w in front
// of the camera (w . forward > 0) has the coordinate q = (w . right) / (w . forward), increasing
// with its angle; `q` holds the corners' coordinates, sorted, and gap k, the directions between
// q[k - 1] and q[k] (the first and last gaps are open), sees `faces[k]` (axis -1: no wall).
struct RgbdRenderer::Gaps {
  Eigen::Vector2d forward = Eigen::Vector2d::Zero(), right = Eigen::Vector2d::Zero();
  std::vector<double> q;
  std::vector<Hit> faces;
};

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

  // Chebyshev distance transform of the wall cells: two chamfer passes with unit weights over
  // the 8-neighbourhood are exact for the L-infinity metric.
  const int W = world.width(), H = world.height();
  skip_.assign(static_cast<std::size_t>(W) * H, 255);
  const auto at = [&](int c, int r) -> std::uint8_t& {
    return skip_[static_cast<std::size_t>(r) * W + c];
  };
  const auto relax = [&](int c, int r, int nc, int nr) {
    if (nc >= 0 && nr >= 0 && nc < W && nr < H)
      at(c, r) = std::min<std::uint8_t>(at(c, r),
                                        static_cast<std::uint8_t>(std::min(255, at(nc, nr) + 1)));
  };
  for (int r = 0; r < H; ++r)
    for (int c = 0; c < W; ++c) {
      if (world.wall(c, r)) {
        at(c, r) = 0;
        continue;
      }
      relax(c, r, c - 1, r);
      relax(c, r, c - 1, r - 1);
      relax(c, r, c, r - 1);
      relax(c, r, c + 1, r - 1);
    }
  for (int r = H - 1; r >= 0; --r)
    for (int c = W - 1; c >= 0; --c) {
      relax(c, r, c + 1, r);
      relax(c, r, c + 1, r + 1);
      relax(c, r, c, r + 1);
      relax(c, r, c - 1, r + 1);
    }

  // Corners of the wall outline: grid points whose four cells are neither all alike nor split
  // by one straight edge (two side by side wall cells).
  const double res = world.resolution();
  for (int r = 0; r <= H; ++r)
    for (int c = 0; c <= W; ++c) {
      const bool a = world.wall(c - 1, r - 1), b = world.wall(c, r - 1);
      const bool e = world.wall(c - 1, r), f = world.wall(c, r);
      const int n = a + b + e + f;
      const bool straight = n == 2 && (a == b || a == e);
      if (n != 0 && n != 4 && !straight) corners_.emplace_back(c * res, r * res);
    }
}

Eigen::Isometry3d RgbdRenderer::cameraPose(const Pose2& base) const {
  Eigen::Isometry3d world_base = Eigen::Isometry3d::Identity();
  world_base.translate(Eigen::Vector3d(base.x, base.y, 0));
  world_base.rotate(Eigen::AngleAxisd(base.theta, Eigen::Vector3d::UnitZ()));
  return world_base * config_.mount.opticalToBase();
}

RgbdRenderer::Hit RgbdRenderer::trace(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                                      std::span<const int> boxes) const {
  Hit hit = traceFloorBoxes(o, d, boxes);
  traceWalls(o, d, hit);
  return hit;
}

RgbdRenderer::Hit RgbdRenderer::traceFloorBoxes(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                                                std::span<const int> boxes) const {
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
  return hit;
}

void RgbdRenderer::traceWalls(const Eigen::Vector3d& o, const Eigen::Vector3d& d, Hit& hit) const {
  // Walls: exact traversal of the grid cells the ray's floor projection crosses, up to the
  // nearest hit so far. In open space it jumps: a cell whose nearest wall cell is k >= 3 cells
  // away (Chebyshev) is the centre of a free square of radius k - 1, which the ray crosses in one
  // step to the cell where it leaves that square.
  const World& w = *world_;
  const double res = w.resolution();
  int col = static_cast<int>(std::floor(o.x() / res));
  int row = static_cast<int>(std::floor(o.y() / res));
  if (w.wall(col, row)) {
    hit = {0.0, kWallX, 0, o.x()};
    return;
  }
  const int step_c = d.x() > 0 ? 1 : -1, step_r = d.y() > 0 ? 1 : -1;
  // Reciprocals: the traversal multiplies where it would divide (inf along an axis not moved on).
  const double inv_x = d.x() != 0 ? 1.0 / d.x() : kInf, inv_y = d.y() != 0 ? 1.0 / d.y() : kInf;
  const double dtx = d.x() != 0 ? res * std::abs(inv_x) : kInf;
  const double dty = d.y() != 0 ? res * std::abs(inv_y) : kInf;
  // Parameter of the next vertical (x) and horizontal (y) cell boundary after cell (col, row).
  const auto boundaries = [&](double& tx, double& ty) {
    tx = d.x() != 0 ? ((col + (step_c > 0 ? 1 : 0)) * res - o.x()) * inv_x : kInf;
    ty = d.y() != 0 ? ((row + (step_r > 0 ? 1 : 0)) * res - o.y()) * inv_y : kInf;
  };
  double tx, ty;
  boundaries(tx, ty);
  const auto wallHit = [&](int axis, double t) {
    // The face is the boundary line crossed: its index along the axis and the side seen.
    const std::int64_t line = axis == 0 ? col + (step_c < 0 ? 1 : 0) : row + (step_r < 0 ? 1 : 0);
    hit.t = t;
    hit.axis = axis;
    hit.key = hash3(axis == 0 ? kWallX : kWallY, line, axis == 0 ? step_c : step_r);
    hit.plane = static_cast<double>(line) * res;
  };
  const auto leaving = [&] {
    // Outside the map nothing stands, and a ray that has left never comes back.
    return (col < 0 && step_c < 0) || (col >= w.width() && step_c > 0) || (row < 0 && step_r < 0) ||
           (row >= w.height() && step_r > 0);
  };
  while (true) {
    const int k = w.inside(col, row) ? skip_[static_cast<std::size_t>(row) * w.width() + col] : 0;
    if (k >= 3) {
      const double ex =
          d.x() != 0 ? ((col + step_c * (k - 1) + (step_c > 0 ? 1 : 0)) * res - o.x()) * inv_x
                     : kInf;
      const double ey =
          d.y() != 0 ? ((row + step_r * (k - 1) + (step_r > 0 ? 1 : 0)) * res - o.y()) * inv_y
                     : kInf;
      const double t_jump = std::min(ex, ey);
      if (t_jump >= hit.t) break;
      const int axis = ex < ey ? 0 : 1;
      // The cell entered: across the square's edge on the exit axis, by position on the other.
      if (axis == 0) {
        col += step_c * k;
        row = std::clamp(static_cast<int>(std::floor((o.y() + t_jump * d.y()) / res)), row - k + 1,
                         row + k - 1);
      } else {
        row += step_r * k;
        col = std::clamp(static_cast<int>(std::floor((o.x() + t_jump * d.x()) / res)), col - k + 1,
                         col + k - 1);
      }
      boundaries(tx, ty);
      if (!w.inside(col, row)) {
        if (leaving()) break;
        continue;
      }
      if (w.wall(col, row)) {
        wallHit(axis, t_jump);
        break;
      }
      continue;
    }
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
      if (leaving()) break;
      continue;
    }
    if (w.wall(col, row)) {
      wallHit(axis, t_enter);
      break;
    }
  }
}

void RgbdRenderer::buildGaps(const Eigen::Vector3d& o, const Eigen::Vector2d& forward,
                             Gaps& gaps) const {
  gaps.forward = forward;
  gaps.right = Eigen::Vector2d(forward.y(), -forward.x());
  gaps.q.clear();
  for (const Eigen::Vector2d& p : corners_) {
    const Eigen::Vector2d w = p - o.head<2>();
    const double ahead = w.dot(gaps.forward);
    if (ahead > 0) gaps.q.push_back(w.dot(gaps.right) / ahead);
  }
  std::sort(gaps.q.begin(), gaps.q.end());
  gaps.q.erase(std::unique(gaps.q.begin(), gaps.q.end()), gaps.q.end());
  // One traversal per gap, along a direction inside it (its middle; 1 beyond the open ends).
  const std::size_t n = gaps.q.size();
  gaps.faces.assign(n + 1, Hit{});
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n + 1, 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t k = range.begin(); k != range.end(); ++k) {
                        const double q = n == 0   ? 0.0
                                         : k == 0 ? gaps.q[0] - 1
                                         : k == n ? gaps.q[n - 1] + 1
                                                  : 0.5 * (gaps.q[k - 1] + gaps.q[k]);
                        const Eigen::Vector2d w = gaps.forward + q * gaps.right;
                        Hit face;
                        traceWalls(o, Eigen::Vector3d(w.x(), w.y(), 0), face);
                        if (face.key == 0) face.axis = -1;
                        gaps.faces[k] = face;
                      }
                    });
}

double RgbdRenderer::castRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir) const {
  std::vector<int> all(world_->furniture().size());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  return trace(origin, dir, std::span<const int>(all)).t;
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

  // Boxes that can be in view, with the pixel rectangle their projection covers (the whole
  // image when a corner is at or behind the camera plane); boxes wholly behind it are dropped.
  struct BoxView {
    int index;
    int u0, u1, v0, v1;
  };
  std::vector<BoxView> views;
  const auto& furniture = world_->furniture();
  const Eigen::Isometry3d world_to_camera = camera_to_world.inverse();
  for (std::size_t i = 0; i < furniture.size(); ++i) {
    const FurnitureBox& b = furniture[i];
    int in_front = 0;
    double umin = kInf, umax = -kInf, vmin = kInf, vmax = -kInf;
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d q = world_to_camera * Eigen::Vector3d((k & 1) ? b.hi.x() : b.lo.x(),
                                                                  (k & 2) ? b.hi.y() : b.lo.y(),
                                                                  (k & 4) ? b.hi.z() : b.lo.z());
      if (q.z() <= 1e-6) continue;
      ++in_front;
      const double u = c.fx * q.x() / q.z() + c.cx, v = c.fy * q.y() / q.z() + c.cy;
      umin = std::min(umin, u);
      umax = std::max(umax, u);
      vmin = std::min(vmin, v);
      vmax = std::max(vmax, v);
    }
    if (in_front == 0) continue;
    BoxView view{static_cast<int>(i), 0, c.width - 1, 0, c.height - 1};
    if (in_front == 8) {  // a convex box projects inside the hull of its corners
      const auto clampTo = [](double x, int hi) {
        return static_cast<int>(std::clamp(x, -1.0, static_cast<double>(hi) + 1));
      };
      view = {static_cast<int>(i), clampTo(std::floor(umin) - 1, c.width - 1),
              clampTo(std::ceil(umax) + 1, c.width - 1),
              clampTo(std::floor(vmin) - 1, c.height - 1),
              clampTo(std::ceil(vmax) + 1, c.height - 1)};
    }
    views.push_back(view);
  }

  // The wall faces by horizontal direction, unless the camera looks (nearly) straight up or
  // down or stands in a wall cell: then every pixel traverses the grid.
  Gaps gaps;
  const Eigen::Vector2d ahead = R.col(2).head<2>();
  const World& w = *world_;
  const bool use_gaps =
      ahead.norm() > 1e-3 && !w.wall(static_cast<int>(std::floor(o.x() / w.resolution())),
                                     static_cast<int>(std::floor(o.y() / w.resolution())));
  if (use_gaps) buildGaps(o, ahead.normalized(), gaps);

  tbb::parallel_for(tbb::blocked_range<int>(0, c.height), [&](const tbb::blocked_range<int>& rows) {
    std::vector<const BoxView*> row_views;
    std::vector<int> pixel_boxes;
    for (int v = rows.begin(); v != rows.end(); ++v) {
      NoiseStream noise{hash3(noise_seed, v, 0x726f77)};  // "row": one stream per row
      row_views.clear();
      for (const BoxView& bv : views)
        if (v >= bv.v0 && v <= bv.v1) row_views.push_back(&bv);
      const Eigen::Vector3d row_dir = R.col(1) * ((v - c.cy) / c.fy) + R.col(2);
      for (int u = 0; u < c.width; ++u) {
        // Optical z of the direction is 1, so t is the depth z.
        const Eigen::Vector3d d = row_dir + R.col(0) * ((u - c.cx) / c.fx);
        pixel_boxes.clear();
        for (const BoxView* bv : row_views)
          if (u >= bv->u0 && u <= bv->u1) pixel_boxes.push_back(bv->index);
        Hit hit = traceFloorBoxes(o, d, pixel_boxes);
        const double front = d.x() * gaps.forward.x() + d.y() * gaps.forward.y();
        if (use_gaps && front > 1e-3 * (std::abs(d.x()) + std::abs(d.y()))) {
          const double q = (d.x() * gaps.right.x() + d.y() * gaps.right.y()) / front;
          const auto k = static_cast<std::size_t>(
              std::upper_bound(gaps.q.begin(), gaps.q.end(), q) - gaps.q.begin());
          const Hit& face = gaps.faces[k];
          // As the traversal computes it: the face's coordinate against the ray's reciprocal.
          const double t =
              face.axis >= 0 ? (face.plane - o[face.axis]) * (1.0 / d[face.axis]) : kInf;
          // A ray through a corner (to rounding) or along a face's line (a camera on a grid
          // line, looking along it): the traversal decides, as its cell rule is the reference.
          const double tie = 1e-9 * (1 + std::abs(q));
          if ((k > 0 && q - gaps.q[k - 1] < tie) || (k < gaps.q.size() && gaps.q[k] - q < tie) ||
              std::isnan(t) || t < 0) {
            traceWalls(o, d, hit);
          } else if (t < hit.t) {
            hit = face;
            hit.t = t;
          }
        } else {
          traceWalls(o, d, hit);
        }
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
        if (c.depth_noise > 0) z += c.depth_noise * z * z * noise.gaussian();
        out.depth[i] = (z >= c.range_min && z <= c.range_max) ? static_cast<float>(z) : 0.0f;
        if (c.image_noise > 0)
          for (int k = 0; k < 3; ++k) {
            const double value = px[k] + c.image_noise * noise.gaussian();
            px[k] = static_cast<std::uint8_t>(std::clamp(value, 0.0, 255.0) + 0.5);
          }
      }
    }
  });
}

}  // namespace tessera::sim
