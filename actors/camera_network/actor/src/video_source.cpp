// VideoSource through libtessera_camera_io.so, loaded once on first use.
#include <tessera/camera_network/video_source.hpp>

#include <tessera/io/module_path.hpp>

#include <dlfcn.h>

#include <algorithm>
#include <cctype>
#include <mutex>

namespace tessera::camera_network {

namespace video_source_detail {

using OpenFn = VideoSource* (*)(const std::string*, int, bool, std::string*);
using ImreadFn = void (*)(const std::string*, cv::Mat*);

struct Module {
  OpenFn open = nullptr;
  ImreadFn imread = nullptr;
  std::string error;
};

constexpr const char* kModuleName = "libtessera_camera_io.so";
// dladdr() of this object names the file this code lives in.
const char kAnchor = 0;

const Module& module() {
  static Module m;
  static std::once_flag once;
  std::call_once(once, [] {
    std::string tried;
    for (const auto& file : io::moduleCandidates(kModuleName, &kAnchor)) {
      void* handle = ::dlopen(file.c_str(), RTLD_NOW | RTLD_LOCAL);
      if (!handle) {
        const char* why = ::dlerror();
        tried += (tried.empty() ? "" : "; ") + file.string() + ": " + (why ? why : "unknown");
        continue;
      }
      m.open = reinterpret_cast<OpenFn>(::dlsym(handle, "tessera_camera_io_open"));
      m.imread = reinterpret_cast<ImreadFn>(::dlsym(handle, "tessera_camera_io_imread"));
      if (m.open && m.imread) return;
      tried += (tried.empty() ? "" : "; ") + file.string() + ": lacks its entry points";
    }
    m.error = std::string("camera I/O: cannot load ") + kModuleName +
              " (it is built beside the tessera binary): " + tried;
  });
  if (!m.error.empty()) throw std::runtime_error(m.error);
  return m;
}

}  // namespace video_source_detail

std::unique_ptr<VideoSource> VideoSource::open(const std::string& source, bool live) {
  const auto& m = video_source_detail::module();
  std::string error;
  const int index = isDeviceIndex(source) ? std::stoi(source) : -1;
  std::unique_ptr<VideoSource> s(m.open(&source, index, live, &error));
  if (!s) throw std::runtime_error(error.empty() ? "cannot be opened" : error);
  return s;
}

bool VideoSource::isDeviceIndex(const std::string& source) {
  return !source.empty() && source.size() < 6 &&
         std::all_of(source.begin(), source.end(),
                     [](unsigned char c) { return std::isdigit(c) != 0; });
}

cv::Mat VideoSource::readImage(const std::string& path) {
  const auto& m = video_source_detail::module();
  cv::Mat image;
  m.imread(&path, &image);
  return image;
}

}  // namespace tessera::camera_network
