// KinectDriverActor ("kinect"): a Kinect v1 through libfreenect as an RGB-D camera
// (docs/architecture.md#device-drivers).
//
// Publishes (local topic name):
//   rgbd  msg::RgbdFrame  640 x 480 colour ("rgb8") and depth ("16UC1", millimetres, 0 = no
//                         reading) paired in time, ~30 Hz, stamped by the device's 60 MHz frame
//                         counter mapped to host time (SensorClock, one per stream). With
//                         registration "device" the depth is libfreenect's, re-projected into the
//                         colour camera (colorRegistered, intrinsics = colour camera); with "none"
//                         it is the IR camera's, converted from raw disparity by the depth model
//                         (intrinsics = depth camera; rgbd_front_end's tracker.register_depth
//                         re-projects it).
//
// Its own I/O thread runs libfreenect's event loop, copies each frame out of libfreenect's
// buffer and publishes pairs; the runtime's threads never wait for the device. A Kinect that is
// missing or unplugged is reopened with exponential back-off. With `recording`, Debian's
// fakenect library plays a fakenect folder in place of the device (checked first: fakenect ends
// the process on a bad one) and the run ends with it. Needs the wall clock.
#pragma once

#include <tessera/drivers/kinect_depth.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace tessera::drivers {

struct KinectActorOptions {
  std::string recording;  ///< a fakenect folder to play instead of the device
  std::string library;    ///< "" = the system's libfreenect (fakenect's with `recording`)
  int device_index = 0;
  std::string registration = "device";
  std::string frame_id = "camera_rgb_optical_frame";
  double max_pair_gap_s = 0.02;
  std::vector<double> depth_camera = {585, 585, 320, 240};
  std::vector<double> color_camera = {525, 525, 319.5, 239.5};
  KinectDepthModel depth;
  double retry_initial_s = 0.5;
  double retry_max_s = 8;

  template <class V>
  void visit(V& v) {
    v("recording", recording,
      "fakenect folder (INDEX.txt) to play through fakenect instead of the device; "
      "`tessera emulate kinect` makes one");
    v("library", library, "libfreenect to load; empty: the system's (or fakenect's)");
    v("device_index", device_index, "which Kinect, when several are plugged in");
    v("registration", registration,
      "device: libfreenect registers depth to colour (real Kinect only); none: raw depth in the "
      "IR camera, converted with `depth`");
    v("frame_id", frame_id, "frame of the published frames");
    v("max_pair_gap_s", max_pair_gap_s, "[s] colour and depth further apart are not paired");
    v("depth_camera", depth_camera, "IR camera intrinsics [fx, fy, cx, cy] px (registration none)");
    v("color_camera", color_camera, "colour camera intrinsics [fx, fy, cx, cy] px");
    v("depth", depth, "raw disparity to metres (registration none)");
    v("retry_initial_s", retry_initial_s, "[s] first wait before reopening a failed device");
    v("retry_max_s", retry_max_s, "[s] longest wait between reopen attempts (doubling)");
  }
};

class KinectDriverActor final : public Actor {
 public:
  explicit KinectDriverActor(KinectActorOptions options);  // throws ConfigError
  ~KinectDriverActor() override;

  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  /// frames, depth_frames, color_frames, dropped_unpaired, corrupt_depth_pixels, reconnects,
  /// open_failures, last_error, cpu_s, latency_ms_median / _p99 / _max (the frame completing a
  /// pair handed over by libfreenect -> published).
  void summarize(Summary& out) const override;

 private:
  void run();
  /// `t0`: when the frame completing the pair reached the callback (for the latency figure).
  void publish(const RgbdPairer::Pair& pair, std::chrono::steady_clock::time_point t0);
  bool waitOrStop(double seconds);

  KinectActorOptions options_;
  bool registered_ = false;
  std::string library_;
  KinectDepthConverter converter_;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::RgbdFrame> rgbd_pub_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> ended_{false};
  bool finished_ = false;
  mutable std::mutex mutex_;  // the figures below
  std::int64_t frames_ = 0, depth_frames_ = 0, color_frames_ = 0, dropped_ = 0;
  std::int64_t corrupt_pixels_ = 0, reconnects_ = 0, open_failures_ = 0;
  double cpu_s_ = 0;
  std::string last_error_;
  std::vector<double> latencies_ms_;
  std::thread thread_;  // last: it uses the members above
};

}  // namespace tessera::drivers
