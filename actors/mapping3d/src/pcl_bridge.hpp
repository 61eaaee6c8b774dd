// The mapping3d side of the PCL bridge: finds libtessera_pcl_bridge.so (pcl_bridge_module.cpp)
// beside the running executable, dlopens it once on first use and wraps its C ABI
// (pcl_bridge_abi.h) for PointCloud. Private to this library's .cpp files (and its tests); the
// module is never unloaded, so the function pointers stay valid for the life of the process.
#pragma once

#include "pcl_bridge_abi.h"

#include <tessera/mapping3d/keyframe_cloud.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace tessera::mapping3d::pcl_bridge {

/// File name of the module.
inline constexpr const char* kModuleName = "libtessera_pcl_bridge.so";

/// A loaded module's entry points.
struct Module {
  std::filesystem::path path;
  decltype(&tessera_pcl_voxel_filter) voxel_filter = nullptr;
  decltype(&tessera_pcl_save_pcd_binary) save_pcd_binary = nullptr;
  decltype(&tessera_pcl_save_ply_binary) save_ply_binary = nullptr;
  decltype(&tessera_pcl_load_pcd) load_pcd = nullptr;
  decltype(&tessera_pcl_load_ply) load_ply = nullptr;
};

/// Where module() looks, in order: the running executable's directory (/proc/self/exe), then
/// its ../lib; then the same two beside the object holding this code (dladdr), when that is
/// another file (this library in a shared object).
std::vector<std::filesystem::path> candidatePaths();

/// Loads the module from exactly `file`: dlopen, every entry point, the ABI version. Throws
/// std::runtime_error "point-cloud support: cannot load FILE: REASON (...)" with dlerror()'s
/// reason. The module stays loaded (also what module() uses; tests call it with other paths).
Module loadModule(const std::filesystem::path& file);

/// The process's module from the first of candidatePaths() that loads, loaded on the first call
/// (thread safe). When none loads, this and every later call throws std::runtime_error naming
/// each path tried and why it failed.
const Module& module();

/// pcl::VoxelGrid at `leaf` (> 0) through the module; the cloud's colours are averaged.
PointCloud voxelFilter(const PointCloud& cloud, float leaf);

/// Binary PCD / binary PLY of `cloud` to `file` (written as named: no temporary here). Return
/// PCL's result, negative when PCL failed (it printed why); throw std::runtime_error with the
/// message of anything PCL threw.
int savePcdBinary(const PointCloud& cloud, const std::string& file);
int savePlyBinary(const PointCloud& cloud, const std::string& file);

/// Reads a PCD / PLY file into `cloud` (colours when it has an rgb or rgba field). Return and
/// throw as the save functions.
int loadPcd(const std::string& file, PointCloud& cloud);
int loadPly(const std::string& file, PointCloud& cloud);

}  // namespace tessera::mapping3d::pcl_bridge
