// Conversions between our PointCloud (Eigen points + R, G, B) and PCL clouds; private to this
// library's .cpp files so PCL never reaches a public header.
#pragma once

#include <tessera/mapping3d/keyframe_cloud.hpp>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <type_traits>

namespace tessera::mapping3d {

/// PointT is pcl::PointXYZ (colours dropped) or pcl::PointXYZRGB (colours copied; the cloud must
/// have them).
template <class PointT>
typename pcl::PointCloud<PointT>::Ptr toPcl(const PointCloud& cloud) {
  auto out = pcl::make_shared<pcl::PointCloud<PointT>>();
  out->points.resize(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    auto& p = out->points[i];
    p.x = cloud.points[i].x();
    p.y = cloud.points[i].y();
    p.z = cloud.points[i].z();
    if constexpr (std::is_same_v<PointT, pcl::PointXYZRGB>) {
      p.r = cloud.colors[i][0];
      p.g = cloud.colors[i][1];
      p.b = cloud.colors[i][2];
    }
  }
  out->width = static_cast<std::uint32_t>(cloud.size());
  out->height = 1;
  out->is_dense = true;
  return out;
}

template <class PointT>
PointCloud fromPcl(const pcl::PointCloud<PointT>& cloud) {
  PointCloud out;
  out.points.reserve(cloud.size());
  constexpr bool kColor = std::is_same_v<PointT, pcl::PointXYZRGB>;
  if constexpr (kColor) out.colors.reserve(cloud.size());
  for (const auto& p : cloud.points) {
    out.points.emplace_back(p.x, p.y, p.z);
    if constexpr (kColor) out.colors.push_back({p.r, p.g, p.b});
  }
  return out;
}

}  // namespace tessera::mapping3d
