// FreenectCamera: one Kinect v1 through libfreenect (docs/architecture.md#device-drivers).
//
// libfreenect is loaded at run time (dlopen) rather than linked, for two reasons: the same
// binary then plays a recording through Debian's fakenect library (a drop-in libfreenect that
// replays a folder, see fakenect_recording.hpp) in the same process as other drivers, and a
// machine without the library gets an error naming it instead of a binary that does not start.
//
// Streams: colour as 640 x 480 RGB; depth either raw (11-bit disparities of the IR camera,
// converted by the driver with KinectDepthModel) or registered (libfreenect's own conversion to
// millimetres, re-projected into the colour camera with the calibration the device stores; real
// devices only: fakenect plays raw depth).
//
// One libfreenect per process: the system's and fakenect share a soname, so a process that
// loaded one by name gets the same one again. Not thread-safe: one thread opens the camera, runs
// processEvents() (which calls the frame callbacks on that thread, with libfreenect's buffers,
// valid only during the call) and closes it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>

namespace tessera::drivers {

/// The library cannot be loaded, has no Kinect, or refused a request; says which and why.
class FreenectError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FreenectCameraOptions {
  std::string library = "libfreenect.so.0.5";  ///< a path or a name the loader finds
  int device_index = 0;
  bool registered_depth = false;  ///< true: libfreenect's registered millimetres
};

class FreenectCamera {
 public:
  /// `data`: the frame (depth: 640 x 480 uint16; colour: 640 x 480 x 3 bytes), `timestamp`:
  /// the device's frame counter.
  using FrameCallback =
      std::function<void(const void* data, std::size_t bytes, std::uint32_t timestamp)>;

  /// Loads the library and resolves its functions; throws FreenectError naming what is missing.
  FreenectCamera(FreenectCameraOptions options, FrameCallback on_depth, FrameCallback on_color);
  ~FreenectCamera();
  FreenectCamera(const FreenectCamera&) = delete;
  FreenectCamera& operator=(const FreenectCamera&) = delete;

  /// Opens the device and starts both streams; throws FreenectError (no device, busy, refused
  /// mode). Closes first if open.
  void open();
  void close();
  bool isOpen() const { return device_ != nullptr; }
  /// Handles what arrived within `timeout_ms` (fakenect: plays the next entry, keeping the
  /// recording's pace). Returns false when the device is gone (or a recording has ended).
  bool processEvents(int timeout_ms);

 private:
  struct Api;  // the library's functions; its callbacks reach the members through it

  FreenectCameraOptions options_;
  FrameCallback on_depth_, on_color_;
  void* handle_ = nullptr;
  Api* api_ = nullptr;
  void* context_ = nullptr;
  void* device_ = nullptr;
  std::size_t depth_bytes_ = 0, color_bytes_ = 0;
  bool fakenect_ = false;
};

}  // namespace tessera::drivers
