// FreenectCamera over a dlopen'ed libfreenect (or fakenect): the few functions the driver needs.
#include <tessera/drivers/freenect_camera.hpp>

#include <tessera/drivers/fakenect_recording.hpp>

#include <dlfcn.h>
#include <libfreenect.h>
#include <sys/time.h>

#include <cstdlib>
#include <memory>
#include <string>

namespace tessera::drivers {

struct FreenectCamera::Api {
  int (*init)(freenect_context**, freenect_usb_context*) = nullptr;
  int (*shutdown)(freenect_context*) = nullptr;
  void (*select_subdevices)(freenect_context*, freenect_device_flags) = nullptr;
  int (*num_devices)(freenect_context*) = nullptr;
  int (*open_device)(freenect_context*, freenect_device**, int) = nullptr;
  int (*close_device)(freenect_device*) = nullptr;
  void (*set_depth_callback)(freenect_device*, freenect_depth_cb) = nullptr;
  void (*set_video_callback)(freenect_device*, freenect_video_cb) = nullptr;
  freenect_frame_mode (*find_depth_mode)(freenect_resolution, freenect_depth_format) = nullptr;
  freenect_frame_mode (*find_video_mode)(freenect_resolution, freenect_video_format) = nullptr;
  int (*set_depth_mode)(freenect_device*, freenect_frame_mode) = nullptr;
  int (*set_video_mode)(freenect_device*, freenect_frame_mode) = nullptr;
  int (*start_depth)(freenect_device*) = nullptr;
  int (*start_video)(freenect_device*) = nullptr;
  int (*stop_depth)(freenect_device*) = nullptr;
  int (*stop_video)(freenect_device*) = nullptr;
  int (*process_events_timeout)(freenect_context*, timeval*) = nullptr;

  static void onDepth(freenect_device* dev, void* data, std::uint32_t timestamp) {
    deliver(dev, data, timestamp, true);
  }
  static void onColor(freenect_device* dev, void* data, std::uint32_t timestamp) {
    deliver(dev, data, timestamp, false);
  }
  static void deliver(freenect_device* dev, void* data, std::uint32_t timestamp, bool depth);
  // The callbacks carry only the device: the camera whose processEvents() runs on this thread
  // is the one they are for (fakenect's freenect_get_user returns nothing useful).
  static thread_local FreenectCamera* current;
};

thread_local FreenectCamera* FreenectCamera::Api::current = nullptr;

void FreenectCamera::Api::deliver(freenect_device* dev, void* data, std::uint32_t timestamp,
                                  bool depth) {
  FreenectCamera* self = current;
  if (!self || !data || dev != self->device_) return;
  if (depth)
    self->on_depth_(data, self->depth_bytes_, timestamp);
  else
    self->on_color_(data, self->color_bytes_, timestamp);
}

namespace freenect_detail {

template <typename F>
void resolve(void* handle, const std::string& library, const char* name, F& out) {
  out = reinterpret_cast<F>(::dlsym(handle, name));
  if (!out)
    throw FreenectError(library + " has no function " + name +
                        " (not libfreenect 0.5, or not libfreenect at all?)");
}

}  // namespace freenect_detail

FreenectCamera::FreenectCamera(FreenectCameraOptions options, FrameCallback on_depth,
                               FrameCallback on_color)
    : options_(std::move(options)), on_depth_(std::move(on_depth)), on_color_(std::move(on_color)) {
  if (options_.device_index < 0)
    throw FreenectError("device index " + std::to_string(options_.device_index) + " is negative");
  handle_ = ::dlopen(options_.library.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle_) {
    const char* why = ::dlerror();
    throw FreenectError("cannot load " + options_.library + ": " + (why ? why : "unknown") +
                        " (Debian: apt-get install libfreenect0.5)");
  }
  auto api = std::make_unique<Api>();
  using freenect_detail::resolve;
  const auto& l = options_.library;
  try {
    resolve(handle_, l, "freenect_init", api->init);
    resolve(handle_, l, "freenect_shutdown", api->shutdown);
    resolve(handle_, l, "freenect_select_subdevices", api->select_subdevices);
    resolve(handle_, l, "freenect_num_devices", api->num_devices);
    resolve(handle_, l, "freenect_open_device", api->open_device);
    resolve(handle_, l, "freenect_close_device", api->close_device);
    resolve(handle_, l, "freenect_set_depth_callback", api->set_depth_callback);
    resolve(handle_, l, "freenect_set_video_callback", api->set_video_callback);
    resolve(handle_, l, "freenect_find_depth_mode", api->find_depth_mode);
    resolve(handle_, l, "freenect_find_video_mode", api->find_video_mode);
    resolve(handle_, l, "freenect_set_depth_mode", api->set_depth_mode);
    resolve(handle_, l, "freenect_set_video_mode", api->set_video_mode);
    resolve(handle_, l, "freenect_start_depth", api->start_depth);
    resolve(handle_, l, "freenect_start_video", api->start_video);
    resolve(handle_, l, "freenect_stop_depth", api->stop_depth);
    resolve(handle_, l, "freenect_stop_video", api->stop_video);
    resolve(handle_, l, "freenect_process_events_timeout", api->process_events_timeout);
  } catch (...) {
    ::dlclose(handle_);
    throw;
  }
  api_ = api.release();
  // fakenect exports the player's subset of the API; the device functions below are not in it.
  fakenect_ = ::dlsym(handle_, "freenect_list_device_attributes") == nullptr;
  if (fakenect_ && options_.registered_depth) {
    close();
    throw FreenectError(options_.library +
                        " is fakenect, libfreenect's recording player: it plays raw depth only "
                        "(registration needs the calibration a real Kinect stores)");
  }
}

FreenectCamera::~FreenectCamera() {
  close();
  delete api_;
  // The library stays loaded: libusb (or fakenect) may keep threads or handlers behind; unloading
  // it under them is what dlclose would risk for nothing.
}

void FreenectCamera::open() {
  close();
  if (fakenect_) {
    // fakenect ends the process on a missing variable, folder or file: check them first.
    const char* folder = std::getenv("FAKENECT_PATH");
    if (!folder || !*folder)
      throw FreenectError("fakenect needs FAKENECT_PATH, the folder of the recording to play");
    try {
      checkFakenectRecording(folder);
    } catch (const FakenectRecordingError& e) {
      throw FreenectError(std::string("fakenect recording: ") + e.what());
    }
  }
  freenect_context* ctx = nullptr;
  if (api_->init(&ctx, nullptr) < 0 || !ctx)
    throw FreenectError("freenect_init failed (libusb cannot start; see the message above)");
  context_ = ctx;
  api_->select_subdevices(ctx, FREENECT_DEVICE_CAMERA);  // the motor and microphones stay free
  const int count = api_->num_devices(ctx);
  if (count <= options_.device_index) {
    close();
    throw FreenectError("no Kinect " + std::to_string(options_.device_index) + ": " +
                        std::to_string(count < 0 ? 0 : count) +
                        " found (plugged in, powered by its adapter, udev rule for plugdev?)");
  }
  freenect_device* dev = nullptr;
  if (api_->open_device(ctx, &dev, options_.device_index) < 0 || !dev) {
    close();
    throw FreenectError("cannot open Kinect " + std::to_string(options_.device_index) +
                        " (in use by another program, or no permission on /dev/bus/usb?)");
  }
  device_ = dev;
  const freenect_frame_mode depth_mode = api_->find_depth_mode(
      FREENECT_RESOLUTION_MEDIUM,
      options_.registered_depth ? FREENECT_DEPTH_REGISTERED : FREENECT_DEPTH_11BIT);
  const freenect_frame_mode video_mode =
      api_->find_video_mode(FREENECT_RESOLUTION_MEDIUM, FREENECT_VIDEO_RGB);
  if (!depth_mode.is_valid || !video_mode.is_valid || depth_mode.width != 640 ||
      video_mode.width != 640) {
    close();
    throw FreenectError("the library offers no 640 x 480 RGB and depth modes");
  }
  depth_bytes_ = static_cast<std::size_t>(depth_mode.bytes);
  color_bytes_ = static_cast<std::size_t>(video_mode.bytes);
  if (api_->set_depth_mode(dev, depth_mode) < 0 || api_->set_video_mode(dev, video_mode) < 0) {
    close();
    throw FreenectError("the Kinect refused the 640 x 480 modes");
  }
  api_->set_depth_callback(dev, &Api::onDepth);
  api_->set_video_callback(dev, &Api::onColor);
  if (api_->start_depth(dev) < 0 || api_->start_video(dev) < 0) {
    close();
    throw FreenectError("the Kinect's streams did not start");
  }
}

void FreenectCamera::close() {
  if (device_) {
    auto* dev = static_cast<freenect_device*>(device_);
    api_->stop_depth(dev);
    api_->stop_video(dev);
    api_->close_device(dev);
    device_ = nullptr;
  }
  if (context_) {
    api_->shutdown(static_cast<freenect_context*>(context_));
    context_ = nullptr;
  }
}

bool FreenectCamera::processEvents(int timeout_ms) {
  if (!device_) return false;
  timeval tv{};
  tv.tv_sec = timeout_ms / 1000;
  tv.tv_usec = (timeout_ms % 1000) * 1000;
  Api::current = this;
  const int r = api_->process_events_timeout(static_cast<freenect_context*>(context_), &tv);
  Api::current = nullptr;
  return r >= 0;
}

}  // namespace tessera::drivers
