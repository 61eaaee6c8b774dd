// libtessera_camera_io.so: the part of marker_camera that needs OpenCV's video and image I/O
// (video_source.hpp says why it is a module). Entry points are extern "C" for dlsym.
#include <tessera/camera_network/video_source.hpp>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <string>

namespace tessera::camera_network {

namespace camera_io_module {

class CaptureSource final : public VideoSource {
 public:
  explicit CaptureSource(cv::VideoCapture capture) : capture_(std::move(capture)) {}
  bool read(cv::Mat& image) override {
    try {
      return capture_.read(image) && !image.empty();
    } catch (const cv::Exception&) {
      return false;
    }
  }

 private:
  cv::VideoCapture capture_;
};

}  // namespace camera_io_module

}  // namespace tessera::camera_network

using tessera::camera_network::VideoSource;

/// A new source (device `index` when >= 0, else `source`), or nullptr with `error` set.
extern "C" __attribute__((visibility("default"))) VideoSource* tessera_camera_io_open(
    const std::string* source, int index, bool live, std::string* error) {
  namespace m = tessera::camera_network::camera_io_module;
  cv::VideoCapture capture;
  bool opened = false;
  try {
    opened = index >= 0 ? capture.open(index) : capture.open(*source);
  } catch (const cv::Exception& e) {  // a backend's error is a failed open, like any other
    *error = "cannot be opened (" + e.msg + ")";
    return nullptr;
  }
  if (!opened) {
    *error = "cannot be opened";
    return nullptr;
  }
  if (live) capture.set(cv::CAP_PROP_BUFFERSIZE, 1);  // recent frames
  return new m::CaptureSource(std::move(capture));
}

/// `path` as grey into `image` (empty when unreadable).
extern "C" __attribute__((visibility("default"))) void tessera_camera_io_imread(
    const std::string* path, cv::Mat* image) {
  try {
    *image = cv::imread(*path, cv::IMREAD_GRAYSCALE);
  } catch (const cv::Exception&) {
    image->release();
  }
}
