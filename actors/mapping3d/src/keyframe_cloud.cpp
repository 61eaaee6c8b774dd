// Back-projection of a depth image into a keyframe cloud, and the PCL voxel filter every cloud of
// this library goes through (in libtessera_pcl_bridge.so, loaded on first use: pcl_bridge.hpp).
#include "pcl_bridge.hpp"

#include <tessera/mapping3d/keyframe_cloud.hpp>

#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera::mapping3d {

PointCloud PointCloud::transformed(const Eigen::Isometry3d& transform) const {
  PointCloud out;
  out.colors = colors;
  out.points.reserve(points.size());
  const Eigen::Isometry3f t = transform.cast<float>();
  for (const auto& p : points) out.points.push_back(t * p);
  return out;
}

void KeyframeCloudOptions::validate() const {
  if (stride < 1) throw std::invalid_argument("stride must be >= 1");
  if (!std::isfinite(min_depth) || min_depth < 0)
    throw std::invalid_argument("min_depth must be finite and >= 0");
  if (!std::isfinite(max_depth) || max_depth <= min_depth)
    throw std::invalid_argument("max_depth must be finite and > min_depth");
  if (!std::isfinite(voxel_leaf) || voxel_leaf < 0)
    throw std::invalid_argument("voxel_leaf must be finite and >= 0");
}

namespace {

std::string sizeText(const cv::Mat& m) {
  return std::to_string(m.cols) + "x" + std::to_string(m.rows);
}

void checkFrame(const visual_slam::PinholeCamera& camera, const visual_slam::RgbdFrame& frame) {
  camera.validate();
  const std::string camera_size =
      std::to_string(camera.width) + "x" + std::to_string(camera.height);
  if (frame.depth.empty()) throw std::invalid_argument("depth: empty image");
  if (frame.depth.type() != CV_16UC1) throw std::invalid_argument("depth: not CV_16UC1");
  if (frame.depth.cols != camera.width || frame.depth.rows != camera.height)
    throw std::invalid_argument("depth: size " + sizeText(frame.depth) + " is not the camera's " +
                                camera_size);
  if (!std::isfinite(frame.depth_scale) || frame.depth_scale <= 0)
    throw std::invalid_argument("depth_scale: must be finite and > 0");
  if (frame.image.empty()) return;
  if (frame.image.type() != CV_8UC3 && frame.image.type() != CV_8UC1)
    throw std::invalid_argument("image: not CV_8UC3 or CV_8UC1");
  if (frame.image.size() != frame.depth.size())
    throw std::invalid_argument("image: size " + sizeText(frame.image) + " is not the depth's " +
                                sizeText(frame.depth));
}

}  // namespace

PointCloud makeKeyframeCloud(const visual_slam::PinholeCamera& camera,
                             const visual_slam::RgbdFrame& frame,
                             const KeyframeCloudOptions& options) {
  options.validate();
  checkFrame(camera, frame);
  const bool color = !frame.image.empty();
  const bool grey = color && frame.image.type() == CV_8UC1;
  const double min_units = options.min_depth * frame.depth_scale;
  const double max_units = options.max_depth * frame.depth_scale;
  PointCloud cloud;
  const auto expected = static_cast<std::size_t>(frame.depth.rows / options.stride + 1) *
                        static_cast<std::size_t>(frame.depth.cols / options.stride + 1);
  cloud.points.reserve(expected);
  if (color) cloud.colors.reserve(expected);
  for (int v = 0; v < frame.depth.rows; v += options.stride) {
    const auto* depth_row = frame.depth.ptr<std::uint16_t>(v);
    for (int u = 0; u < frame.depth.cols; u += options.stride) {
      const std::uint16_t d = depth_row[u];
      if (d == 0 || d < min_units || d > max_units) continue;
      const double z = d / frame.depth_scale;
      cloud.points.push_back(camera.backProject(u, v, z).cast<float>());
      if (!color) continue;
      if (grey) {
        const std::uint8_t g = frame.image.at<std::uint8_t>(v, u);
        cloud.colors.push_back({g, g, g});
      } else {
        const auto& c = frame.image.at<cv::Vec3b>(v, u);
        cloud.colors.push_back({c[0], c[1], c[2]});
      }
    }
  }
  return voxelFilter(cloud, options.voxel_leaf);
}

PointCloud voxelFilter(const PointCloud& cloud, double leaf) {
  if (!std::isfinite(leaf)) throw std::invalid_argument("voxel leaf must be finite");
  if (leaf <= 0 || cloud.empty()) return cloud;
  // PointXYZRGB when the cloud has colours (averaged with the positions, VoxelGrid's default),
  // PointXYZ otherwise.
  return pcl_bridge::voxelFilter(cloud, static_cast<float>(leaf));
}

}  // namespace tessera::mapping3d
