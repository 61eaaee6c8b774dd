// Loading libtessera_pcl_bridge.so (dlopen, once, beside the executable) and the PointCloud
// wrappers over its C ABI. PCL is never linked into the executables: only a run that filters or
// reads or writes a cloud maps it (see pcl_bridge_module.cpp for why).
#include "pcl_bridge.hpp"

#include <tessera/io/module_path.hpp>

#include <dlfcn.h>

#include <array>
#include <cstdint>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <system_error>
#include <utility>

namespace tessera::mapping3d::pcl_bridge {

namespace fs = std::filesystem;

namespace {

// Why a load failed is often a missing build step: say where the module comes from.
constexpr const char* kBuiltWhere = "it is built beside the tessera binary";

// Room for PCL's exception messages (PCLException adds file and line).
constexpr std::size_t kErrorSize = 1024;

// dladdr() of this object names the file this code lives in.
const char kAnchor = 0;

// dlerror() after a failed dlopen or dlsym, without the file name it usually starts with (the
// caller's message names it already).
std::string dlReason(const fs::path& file) {
  const char* e = dlerror();
  std::string reason = e != nullptr ? e : "unknown dlopen error";
  const std::string prefix = file.string() + ": ";
  if (reason.compare(0, prefix.size(), prefix) == 0) reason.erase(0, prefix.size());
  return reason;
}

template <class Fn>
bool findSymbol(void* handle, const char* name, Fn& fn, std::string& reason) {
  dlerror();  // clear a stale error
  void* symbol = dlsym(handle, name);
  if (symbol == nullptr) {
    const char* e = dlerror();
    reason = std::string("missing ") + name + (e != nullptr ? std::string(" (") + e + ")" : "");
    return false;
  }
  fn = reinterpret_cast<Fn>(symbol);
  return true;
}

// Loads `file` into `out`, or returns false with `reason`.
bool tryLoad(const fs::path& file, Module& out, std::string& reason) {
  // RTLD_LOCAL: PCL's and VTK's symbols stay out of the global scope; the module is reached
  // through the handle only.
  void* handle = dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (handle == nullptr) {
    reason = dlReason(file);
    return false;
  }
  Module m;
  m.path = file;
  decltype(&tessera_pcl_bridge_abi_version) version = nullptr;
  bool ok = findSymbol(handle, "tessera_pcl_bridge_abi_version", version, reason);
  if (ok && version() != TESSERA_PCL_BRIDGE_ABI_VERSION) {
    reason = "ABI version " + std::to_string(version()) + ", expected " +
             std::to_string(TESSERA_PCL_BRIDGE_ABI_VERSION) + " (a stale build?)";
    ok = false;
  }
  ok = ok && findSymbol(handle, "tessera_pcl_voxel_filter", m.voxel_filter, reason) &&
       findSymbol(handle, "tessera_pcl_save_pcd_binary", m.save_pcd_binary, reason) &&
       findSymbol(handle, "tessera_pcl_save_ply_binary", m.save_ply_binary, reason) &&
       findSymbol(handle, "tessera_pcl_load_pcd", m.load_pcd, reason) &&
       findSymbol(handle, "tessera_pcl_load_ply", m.load_ply, reason);
  if (!ok) {
    dlclose(handle);
    return false;
  }
  // Never closed: PCL's and VTK's static state would be torn down under any cloud still in use,
  // and the process keeps point-cloud support once it has needed it.
  out = std::move(m);
  return true;
}

// Result of the one-time load behind module().
struct Loaded {
  std::once_flag once;
  Module module;
  std::string error;  // empty when `module` is loaded
};

Loaded& loaded() {
  static Loaded l;
  return l;
}

// Receives a cloud from the module into `cloud`; an exception (bad_alloc) is kept for the caller
// to rethrow, since it must not unwind through the module's C frames.
struct CloudSink {
  PointCloud* cloud;
  std::exception_ptr error;
};

int receiveCloud(void* context, const float* xyz, const std::uint8_t* rgb,
                 std::size_t count) noexcept {
  auto& sink = *static_cast<CloudSink*>(context);
  try {
    PointCloud out;
    out.points.reserve(count);
    for (std::size_t i = 0; i < count; ++i)
      out.points.emplace_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    if (rgb != nullptr) {
      out.colors.reserve(count);
      for (std::size_t i = 0; i < count; ++i)
        out.colors.push_back({rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]});
    }
    *sink.cloud = std::move(out);
    return 0;
  } catch (...) {
    sink.error = std::current_exception();
    return 1;
  }
}

// The ABI reads a cloud as flat arrays: PointCloud's vectors are laid out exactly so.
static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float));
static_assert(sizeof(std::array<std::uint8_t, 3>) == 3);

const float* xyzOf(const PointCloud& cloud) {
  return cloud.points.empty() ? nullptr : cloud.points.front().data();
}

const std::uint8_t* rgbOf(const PointCloud& cloud) {
  return cloud.hasColor() ? cloud.colors.front().data() : nullptr;
}

// A bridge result as the old direct PCL calls behaved: PCL's own failure code is returned (the
// callers name the file), what PCL threw is thrown again, a sink's exception is rethrown.
int checked(int code, const char* error, const CloudSink* sink) {
  if (code == TESSERA_PCL_EXCEPTION) throw std::runtime_error(error);
  if (code == TESSERA_PCL_SINK_FAILED) {
    if (sink != nullptr && sink->error) std::rethrow_exception(sink->error);
    throw std::runtime_error("PCL bridge: receiving a cloud failed");
  }
  return code;
}

void checkColors(const PointCloud& cloud) {
  if (cloud.hasColor() && cloud.colors.size() != cloud.points.size())
    throw std::invalid_argument("cloud: " + std::to_string(cloud.colors.size()) + " colours for " +
                                std::to_string(cloud.points.size()) + " points");
}

}  // namespace

std::vector<fs::path> candidatePaths() {
  return io::moduleCandidates(kModuleName, &kAnchor);
}

Module loadModule(const fs::path& file) {
  Module m;
  std::string reason;
  if (!tryLoad(file, m, reason))
    throw std::runtime_error("point-cloud support: cannot load " + file.string() + ": " + reason +
                             " (" + kBuiltWhere + ")");
  return m;
}

const Module& module() {
  Loaded& l = loaded();
  std::call_once(l.once, [&l] {
    const auto files = candidatePaths();
    std::string tried;
    for (const auto& file : files) {
      std::string reason;
      if (tryLoad(file, l.module, reason)) return;
      tried += (tried.empty() ? "" : "; ") + file.string() + ": " + reason;
    }
    if (files.empty()) tried = "the executable's directory is unknown (no /proc/self/exe)";
    l.error = "point-cloud support: cannot load " + std::string(kModuleName) + " (" + kBuiltWhere +
              "): " + tried;
  });
  if (!l.error.empty()) throw std::runtime_error(l.error);
  return l.module;
}

PointCloud voxelFilter(const PointCloud& cloud, float leaf) {
  checkColors(cloud);
  const Module& m = module();
  PointCloud out;
  CloudSink sink{&out, {}};
  char error[kErrorSize] = "";
  const int code = checked(m.voxel_filter(xyzOf(cloud), rgbOf(cloud), cloud.size(), leaf,
                                          receiveCloud, &sink, error, sizeof error),
                           error, &sink);
  if (code < 0) throw std::runtime_error("PCL voxel filter failed");
  return out;
}

int savePcdBinary(const PointCloud& cloud, const std::string& file) {
  checkColors(cloud);
  const Module& m = module();
  char error[kErrorSize] = "";
  return checked(m.save_pcd_binary(file.c_str(), xyzOf(cloud), rgbOf(cloud), cloud.size(), error,
                                   sizeof error),
                 error, nullptr);
}

int savePlyBinary(const PointCloud& cloud, const std::string& file) {
  checkColors(cloud);
  const Module& m = module();
  char error[kErrorSize] = "";
  return checked(m.save_ply_binary(file.c_str(), xyzOf(cloud), rgbOf(cloud), cloud.size(), error,
                                   sizeof error),
                 error, nullptr);
}

int loadPcd(const std::string& file, PointCloud& cloud) {
  const Module& m = module();
  CloudSink sink{&cloud, {}};
  char error[kErrorSize] = "";
  return checked(m.load_pcd(file.c_str(), receiveCloud, &sink, error, sizeof error), error, &sink);
}

int loadPly(const std::string& file, PointCloud& cloud) {
  const Module& m = module();
  CloudSink sink{&cloud, {}};
  char error[kErrorSize] = "";
  return checked(m.load_ply(file.c_str(), receiveCloud, &sink, error, sizeof error), error, &sink);
}

}  // namespace tessera::mapping3d::pcl_bridge
