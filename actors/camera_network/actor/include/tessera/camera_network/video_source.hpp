// VideoSource: frames from a camera device, a stream, a video file (OpenCV's VideoCapture) and
// image files (OpenCV's imread), for marker_camera.
//
// OpenCV's video and image I/O pull in some 270 shared libraries (GStreamer, FFmpeg, GDAL,
// poppler…): about 55 MB of resident memory in every process that links them, whether a profile
// opens a camera or not (docs/architecture.md#device-drivers). They live in a module,
// libtessera_camera_io.so, loaded the first time a VideoSource is opened or an image read.
// Not thread-safe per source.
#pragma once

#include <opencv2/core.hpp>

#include <memory>
#include <stdexcept>
#include <string>

namespace tessera::camera_network {

class VideoSource {
 public:
  virtual ~VideoSource() = default;
  /// The next frame as the backend gives it (BGR or grey); false at the end, on a failed read
  /// or a backend error.
  virtual bool read(cv::Mat& image) = 0;

  /// Opens a device index ("0"), a stream URL or a video file; `live`: keep only the newest
  /// frames. Throws std::runtime_error with the reason (the module or the source).
  static std::unique_ptr<VideoSource> open(const std::string& source, bool live);
  /// `source` names a device by its index ("0".."99999") rather than a path or URL.
  static bool isDeviceIndex(const std::string& source);
  /// An image file as grey; empty when it cannot be read. Throws std::runtime_error when the
  /// module cannot be loaded.
  static cv::Mat readImage(const std::string& path);
};

}  // namespace tessera::camera_network
