// libtessera_pcl_bridge.so: every use of PCL in Tessera (voxel filter, PCD / PLY files) behind
// the C ABI of pcl_bridge_abi.h. It is a module the mapping3d core dlopens on first use
// (pcl_bridge.cpp), not a link dependency: PCL drags VTK, OpenNI, X11 and more in, ~30 MB
// resident merely by being loaded, which a run that never touches a point cloud should not pay.
// Only the five entry points are exported (hidden visibility otherwise); nothing of PCL or of
// this file's C++ types crosses the boundary.

// PCL's prebuilt libraries allocate point vectors (Eigen::aligned_allocator) with plain malloc,
// as Eigen does on 64-bit glibc; under AddressSanitizer Eigen switches this file to its own
// over-allocating scheme, and freeing a cloud VoxelGrid filled would then corrupt the heap (ASan
// reports it). A module's copies of PCL's templates do not interpose PCL's own as an
// executable's do, so the module must allocate as PCL's libraries assume.
#if defined(__SANITIZE_ADDRESS__) && !defined(EIGEN_MALLOC_ALREADY_ALIGNED)
#define EIGEN_MALLOC_ALREADY_ALIGNED 1
#endif

#include "pcl_bridge_abi.h"

#include <pcl/conversions.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <cstring>
#include <exception>
#include <type_traits>
#include <vector>

#define TESSERA_PCL_EXPORT extern "C" __attribute__((visibility("default")))

namespace tessera::mapping3d::pcl_module {
namespace {

template <class PointT>
constexpr bool kHasColor = std::is_same_v<PointT, pcl::PointXYZRGB>;

/// PointT is pcl::PointXYZ (rgb ignored) or pcl::PointXYZRGB (rgb must be given).
template <class PointT>
typename pcl::PointCloud<PointT>::Ptr toPcl(const float* xyz, const std::uint8_t* rgb,
                                            std::size_t count) {
  auto out = pcl::make_shared<pcl::PointCloud<PointT>>();
  out->points.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    auto& p = out->points[i];
    p.x = xyz[3 * i];
    p.y = xyz[3 * i + 1];
    p.z = xyz[3 * i + 2];
    if constexpr (kHasColor<PointT>) {
      p.r = rgb[3 * i];
      p.g = rgb[3 * i + 1];
      p.b = rgb[3 * i + 2];
    }
  }
  out->width = static_cast<std::uint32_t>(count);
  out->height = 1;
  out->is_dense = true;
  return out;
}

/// Flattens `cloud` into the ABI's arrays and hands them to `sink`.
template <class PointT>
int emit(const pcl::PointCloud<PointT>& cloud, tessera_pcl_sink sink, void* context) {
  const std::size_t n = cloud.size();
  std::vector<float> xyz(3 * n);
  std::vector<std::uint8_t> rgb(kHasColor<PointT> ? 3 * n : 0);
  for (std::size_t i = 0; i < n; ++i) {
    const auto& p = cloud.points[i];
    xyz[3 * i] = p.x;
    xyz[3 * i + 1] = p.y;
    xyz[3 * i + 2] = p.z;
    if constexpr (kHasColor<PointT>) {
      rgb[3 * i] = p.r;
      rgb[3 * i + 1] = p.g;
      rgb[3 * i + 2] = p.b;
    }
  }
  const std::uint8_t* colors = kHasColor<PointT> ? rgb.data() : nullptr;
  return sink(context, xyz.data(), colors, n) == 0 ? TESSERA_PCL_OK : TESSERA_PCL_SINK_FAILED;
}

/// pcl::io returns a negative code on failure (and prints why).
int fromPclCode(int code) {
  return code < 0 ? TESSERA_PCL_FAILED : TESSERA_PCL_OK;
}

void setError(char* error, std::size_t size, const char* message) {
  if (error == nullptr || size == 0) return;
  const std::size_t n = std::min(std::strlen(message), size - 1);
  std::memcpy(error, message, n);
  error[n] = '\0';
}

/// Runs `body`, turning any exception into TESSERA_PCL_EXCEPTION and its message: a C++
/// exception must not unwind into the caller through a C interface.
template <class Body>
int guarded(char* error, std::size_t error_size, Body&& body) noexcept {
  try {
    return body();
  } catch (const std::exception& e) {
    setError(error, error_size, e.what());
  } catch (...) {
    setError(error, error_size, "unknown exception in the PCL bridge");
  }
  return TESSERA_PCL_EXCEPTION;
}

template <class PointT>
int voxelFilterAs(const float* xyz, const std::uint8_t* rgb, std::size_t count, float leaf,
                  tessera_pcl_sink sink, void* context) {
  pcl::VoxelGrid<PointT> grid;
  grid.setInputCloud(toPcl<PointT>(xyz, rgb, count));
  grid.setLeafSize(leaf, leaf, leaf);
  pcl::PointCloud<PointT> out;
  grid.filter(out);
  return emit(out, sink, context);
}

/// Calls write(cloud) with the cloud as PointXYZRGB when it has colours, PointXYZ otherwise.
template <class Write>
int writeEither(const float* xyz, const std::uint8_t* rgb, std::size_t count, Write&& write) {
  if (rgb != nullptr) return write(*toPcl<pcl::PointXYZRGB>(xyz, rgb, count));
  return write(*toPcl<pcl::PointXYZ>(xyz, rgb, count));
}

bool hasRgb(const pcl::PCLPointCloud2& blob) {
  return std::any_of(blob.fields.begin(), blob.fields.end(),
                     [](const auto& f) { return f.name == "rgb" || f.name == "rgba"; });
}

int emitBlob(const pcl::PCLPointCloud2& blob, tessera_pcl_sink sink, void* context) {
  if (hasRgb(blob)) {
    pcl::PointCloud<pcl::PointXYZRGB> c;
    pcl::fromPCLPointCloud2(blob, c);
    return emit(c, sink, context);
  }
  pcl::PointCloud<pcl::PointXYZ> c;
  pcl::fromPCLPointCloud2(blob, c);
  return emit(c, sink, context);
}

}  // namespace
}  // namespace tessera::mapping3d::pcl_module

namespace pm = tessera::mapping3d::pcl_module;

TESSERA_PCL_EXPORT int tessera_pcl_bridge_abi_version(void) {
  return TESSERA_PCL_BRIDGE_ABI_VERSION;
}

TESSERA_PCL_EXPORT int tessera_pcl_voxel_filter(const float* xyz, const uint8_t* rgb, size_t count,
                                                float leaf, tessera_pcl_sink sink,
                                                void* sink_context, char* error,
                                                size_t error_size) {
  return pm::guarded(error, error_size, [&] {
    return rgb != nullptr
               ? pm::voxelFilterAs<pcl::PointXYZRGB>(xyz, rgb, count, leaf, sink, sink_context)
               : pm::voxelFilterAs<pcl::PointXYZ>(xyz, rgb, count, leaf, sink, sink_context);
  });
}

TESSERA_PCL_EXPORT int tessera_pcl_save_pcd_binary(const char* path, const float* xyz,
                                                   const uint8_t* rgb, size_t count, char* error,
                                                   size_t error_size) {
  return pm::guarded(error, error_size, [&] {
    return pm::writeEither(xyz, rgb, count, [&](const auto& c) {
      return pm::fromPclCode(pcl::io::savePCDFileBinary(path, c));
    });
  });
}

TESSERA_PCL_EXPORT int tessera_pcl_save_ply_binary(const char* path, const float* xyz,
                                                   const uint8_t* rgb, size_t count, char* error,
                                                   size_t error_size) {
  return pm::guarded(error, error_size, [&] {
    return pm::writeEither(xyz, rgb, count, [&](const auto& c) {
      // No camera element: CloudCompare and pcl_viewer need only the vertices.
      return pm::fromPclCode(pcl::PLYWriter().write(path, c, true, false));
    });
  });
}

TESSERA_PCL_EXPORT int tessera_pcl_load_pcd(const char* path, tessera_pcl_sink sink,
                                            void* sink_context, char* error, size_t error_size) {
  return pm::guarded(error, error_size, [&] {
    pcl::PCLPointCloud2 blob;
    if (pcl::io::loadPCDFile(path, blob) < 0) return TESSERA_PCL_FAILED;
    return pm::emitBlob(blob, sink, sink_context);
  });
}

TESSERA_PCL_EXPORT int tessera_pcl_load_ply(const char* path, tessera_pcl_sink sink,
                                            void* sink_context, char* error, size_t error_size) {
  return pm::guarded(error, error_size, [&] {
    pcl::PCLPointCloud2 blob;
    if (pcl::io::loadPLYFile(path, blob) < 0) return TESSERA_PCL_FAILED;
    return pm::emitBlob(blob, sink, sink_context);
  });
}
