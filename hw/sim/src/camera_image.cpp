// Rendered ceiling-camera images: see camera_image.hpp.
#include <tessera/sim/camera_image.hpp>

#include <Eigen/LU>
#include <opencv2/aruco.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <mutex>
#include <stdexcept>
#include <utility>
#include <vector>

namespace tessera::sim {

namespace camera_image_detail {

constexpr int kTextureSize = 512;            // texture side [texels]; the texture is periodic
constexpr double kTextureResolution = 0.02;  // [m / texel] -> period 10.24 m
constexpr float kFloorGrey = 120.0f;         // mean floor brightness [grey levels]
constexpr float kNoFloorGrey = 128.0f;       // pixels whose ray misses the floor
constexpr float kMarkerBlack = 25.0f;        // printed black and white as the camera sees them
constexpr float kMarkerWhite = 225.0f;
constexpr int kMarkerCellPx = 16;   // marker image pixels per marker cell
constexpr int kSupersample = 4;     // marker area sampling, per axis
constexpr int kDictionaryIds = 50;  // DICT_4X4_50

/// A periodic lattice of uniform(-1, 1) values upsampled by an integer factor; wrapping before
/// resizing keeps the result periodic.
cv::Mat periodicUpsample(int cells, int factor, int interpolation, std::mt19937_64& rng) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  cv::Mat lattice(cells, cells, CV_32F);
  for (int r = 0; r < cells; ++r)
    for (int c = 0; c < cells; ++c) lattice.at<float>(r, c) = u(rng);
  constexpr int pad = 2;
  cv::Mat padded, big;
  cv::copyMakeBorder(lattice, padded, pad, pad, pad, pad, cv::BORDER_WRAP);
  cv::resize(padded, big, cv::Size(), factor, factor, interpolation);
  return big(cv::Rect(pad * factor, pad * factor, cells * factor, cells * factor)).clone();
}

/// The floor texture (CV_32F, kTextureSize^2, periodic): two scales of smooth noise and tiles.
cv::Mat floorTexture(int seed) {
  std::mt19937_64 rng(static_cast<std::uint64_t>(seed) * 0x9E3779B97F4A7C15ull + 12345u);
  const cv::Mat coarse = periodicUpsample(32, kTextureSize / 32, cv::INTER_CUBIC, rng);  // 0.32 m
  const cv::Mat fine = periodicUpsample(128, kTextureSize / 128, cv::INTER_CUBIC, rng);  // 8 cm
  const cv::Mat tiles = periodicUpsample(32, kTextureSize / 32, cv::INTER_NEAREST, rng);
  cv::Mat texture = kFloorGrey + 22.0f * coarse + 8.0f * fine + 8.0f * tiles;
  return texture;
}

/// floorTexture(seed), computed once per seed and kept (the last few seeds). The texture is never
/// written after it is made, so callers may share it.
cv::Mat cachedFloorTexture(int seed) {
  static std::mutex mutex;
  static std::vector<std::pair<int, cv::Mat>> cache;
  const std::lock_guard lock(mutex);
  for (const auto& [s, texture] : cache)
    if (s == seed) return texture;
  if (cache.size() >= 4) cache.erase(cache.begin());
  cache.emplace_back(seed, floorTexture(seed));
  return cache.back().second;
}

/// Floor: every pixel's floor point through H^-1, looked up in the periodic texture.
cv::Mat renderFloor(const EnvironmentCamera& camera, const cv::Mat& texture) {
  const int w = camera.intrinsics().width_px, h = camera.intrinsics().height_px;
  const Eigen::Matrix3d h_inv = camera.homography().inverse();
  cv::Mat map_x(h, w, CV_32F), map_y(h, w, CV_32F);
  cv::Mat no_floor(h, w, CV_8U, cv::Scalar(0));
  const double n = kTextureSize, scale = 1.0 / kTextureResolution;
  bool any_missing = false;
  for (int v = 0; v < h; ++v) {
    float* mx = map_x.ptr<float>(v);
    float* my = map_y.ptr<float>(v);
    for (int u = 0; u < w; ++u) {
      const Eigen::Vector3d q = h_inv * Eigen::Vector3d(u, v, 1.0);
      if (!(q.z() > 0)) {  // the ray meets the floor behind the camera: no floor here
        mx[u] = my[u] = 0;
        no_floor.at<std::uint8_t>(v, u) = 1;
        any_missing = true;
        continue;
      }
      double tx = q.x() / q.z() * scale, ty = q.y() / q.z() * scale;
      tx -= n * std::floor(tx / n);
      ty -= n * std::floor(ty / n);
      mx[u] = static_cast<float>(tx);
      my[u] = static_cast<float>(ty);
    }
  }
  cv::Mat floor;
  cv::remap(texture, floor, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_WRAP);
  if (any_missing) floor.setTo(kNoFloorGrey, no_floor);
  return floor;
}

cv::Matx33d toMatx(const Eigen::Matrix3d& m) {
  cv::Matx33d out;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out(r, c) = m(r, c);
  return out;
}

/// Draws the marker (with its quiet zone) over `image` (CV_32F), area-sampled.
void drawMarkerPatch(const EnvironmentCamera& camera, const Pose2& pose,
                     const CameraImageOptions& options, cv::Mat& image) {
  const int side_px = 6 * kMarkerCellPx;  // 4 x 4 bits and a one-cell black border
  const int quiet = kMarkerCellPx;
  const int total = side_px + 2 * quiet;
  cv::Mat marker8;
  cv::aruco::drawMarker(cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50),
                        options.marker_id, side_px, marker8, 1);
  cv::Mat padded8, marker;
  cv::copyMakeBorder(marker8, padded8, quiet, quiet, quiet, quiet, cv::BORDER_CONSTANT, 255);
  padded8.convertTo(marker, CV_32F, (kMarkerWhite - kMarkerBlack) / 255.0, kMarkerBlack);
  const cv::Mat alpha(total, total, CV_32F, cv::Scalar(1.0));

  // Marker image pixel (c, r) -> marker frame: the image's top edge faces +x (forward), its
  // left edge +y, so x = -(r - cc) k and y = -(c - cc) k about the image centre cc.
  const double k = options.marker_size_m / side_px, cc = 0.5 * (total - 1);
  Eigen::Matrix3d a;
  a << 0, -k, k * cc, -k, 0, k * cc, 0, 0, 1;
  const Eigen::Matrix3d m = camera.homography() * pose.matrix() * a;

  // The quiet zone's outline in the image; give up when it reaches behind the camera.
  double u0 = 1e300, v0 = 1e300, u1 = -1e300, v1 = -1e300;
  for (const Eigen::Vector2d& corner :
       {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(total - 0.5, -0.5),
        Eigen::Vector2d(total - 0.5, total - 0.5), Eigen::Vector2d(-0.5, total - 0.5)}) {
    const Eigen::Vector3d q = m * corner.homogeneous();
    if (!(q.z() > 0)) return;
    u0 = std::min(u0, q.x() / q.z());
    u1 = std::max(u1, q.x() / q.z());
    v0 = std::min(v0, q.y() / q.z());
    v1 = std::max(v1, q.y() / q.z());
  }
  const int w = image.cols, h = image.rows;
  const double x0 = std::max(0.0, std::floor(u0) - 1), y0 = std::max(0.0, std::floor(v0) - 1);
  const double x1 = std::min<double>(w, std::ceil(u1) + 2),
               y1 = std::min<double>(h, std::ceil(v1) + 2);
  if (!(x1 > x0) || !(y1 > y0)) return;
  const cv::Rect roi(static_cast<int>(x0), static_cast<int>(y0), static_cast<int>(x1 - x0),
                     static_cast<int>(y1 - y0));

  // Supersampled ROI: 1x pixel coordinate p (pixel centres at integers) sits at
  // S (p - x0 + 0.5) - 0.5 in the supersampled patch.
  const double s = kSupersample;
  Eigen::Matrix3d t;
  t << s, 0, s * (0.5 - roi.x) - 0.5, 0, s, s * (0.5 - roi.y) - 0.5, 0, 0, 1;
  const cv::Matx33d warp = toMatx(t * m);
  const cv::Size big(roi.width * kSupersample, roi.height * kSupersample);
  cv::Mat marker_big, alpha_big, marker_small, alpha_small;
  cv::warpPerspective(marker, marker_big, warp, big, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
  cv::warpPerspective(alpha, alpha_big, warp, big, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
  cv::resize(marker_big, marker_small, roi.size(), 0, 0, cv::INTER_AREA);
  cv::resize(alpha_big, alpha_small, roi.size(), 0, 0, cv::INTER_AREA);
  // marker_small is premultiplied by coverage (the warp's border is 0).
  cv::Mat patch = image(roi);
  const cv::Mat blended = patch.mul(1.0f - alpha_small) + marker_small;
  blended.copyTo(patch);
}

/// Draws the marker over `image` (CV_32F, the floor; changed), blurs it, adds the noise (one draw
/// from `rng`, the noise field in `noise`) and writes the CV_8UC1 result to `out`.
void finishImage(const EnvironmentCamera& camera, const Pose2& marker_pose,
                 const CameraImageOptions& options, std::mt19937_64& rng, cv::Mat& image,
                 cv::Mat& noise, cv::Mat& out) {
  if (!allFinite(marker_pose))
    throw std::invalid_argument("camera image: marker pose is not finite");
  drawMarkerPatch(camera, marker_pose, options, image);
  if (options.blur_px > 0)
    cv::GaussianBlur(image, image, cv::Size(0, 0), options.blur_px, options.blur_px,
                     cv::BORDER_REPLICATE);
  // One draw from the caller's generator seeds the per-pixel noise.
  cv::RNG noise_rng(static_cast<std::uint64_t>(rng()));
  if (options.noise_std > 0) {
    noise.create(image.size(), CV_32F);
    noise_rng.fill(noise, cv::RNG::NORMAL, 0.0, options.noise_std);
    image += noise;
  }
  image.convertTo(out, CV_8U);  // rounds and saturates to 0..255
}

}  // namespace camera_image_detail

ConfigCheck CameraImageOptions::check() const {
  ConfigCheck c;
  c.positive("marker_size_m", marker_size_m)
      .require(marker_id >= 0 && marker_id < camera_image_detail::kDictionaryIds, "marker_id",
               "must be in [0, 50) (DICT_4X4_50)", marker_id)
      .nonNegative("blur_px", blur_px)
      .nonNegative("noise_std", noise_std);
  return c;
}

cv::Mat renderCameraImage(const EnvironmentCamera& camera, const Pose2& marker_pose,
                          const CameraImageOptions& options, std::mt19937_64& rng) {
  namespace d = camera_image_detail;
  options.validate();
  if (!allFinite(marker_pose))
    throw std::invalid_argument("camera image: marker pose is not finite");
  cv::Mat image = d::renderFloor(camera, d::cachedFloorTexture(options.floor_texture_seed));
  cv::Mat noise, out;
  d::finishImage(camera, marker_pose, options, rng, image, noise, out);
  return out;
}

CameraImageRenderer::CameraImageRenderer(const EnvironmentCamera& camera,
                                         const CameraImageOptions& options)
    : camera_(camera), options_(options) {
  namespace d = camera_image_detail;
  options_.validate();
  floor_ = d::renderFloor(camera_, d::cachedFloorTexture(options_.floor_texture_seed));
}

void CameraImageRenderer::render(const Pose2& marker_pose, std::mt19937_64& rng, cv::Mat& out) {
  floor_.copyTo(work_);  // reuses work_'s buffer
  camera_image_detail::finishImage(camera_, marker_pose, options_, rng, work_, noise_, out);
}

std::optional<std::array<Eigen::Vector2d, 4>> markerCornerPixels(const EnvironmentCamera& camera,
                                                                 const Pose2& marker_pose,
                                                                 double marker_size_m) {
  const double hs = 0.5 * marker_size_m;
  const std::array<Eigen::Vector2d, 4> local = {Eigen::Vector2d(hs, hs), Eigen::Vector2d(hs, -hs),
                                                Eigen::Vector2d(-hs, -hs),
                                                Eigen::Vector2d(-hs, hs)};
  std::array<Eigen::Vector2d, 4> out;
  for (std::size_t i = 0; i < 4; ++i) {
    const auto px = camera.project(marker_pose.translation() + marker_pose.rotation() * local[i]);
    if (!px) return std::nullopt;
    out[i] = *px;
  }
  return out;
}

}  // namespace tessera::sim
