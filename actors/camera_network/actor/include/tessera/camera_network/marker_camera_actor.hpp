// marker_camera actor: one real environment (ceiling) camera. Grabs frames from a V4L2 device, a
// network stream, a video file or a folder of images, or takes them from a topic (the simulated
// camera_network's rendered camera_images), finds the robot's ArUco marker in them
// (MarkerDetector) and reports it like the simulated camera_network actor does.
//
// Subscribes: nothing, or with source "topic:NAME":
//   NAME               msg::Image            keep_latest(image_queue); only the images whose
//                                            frame id is "camera_<camera_id>" ("mono8", "bgr8"
//                                            or "rgb8"), the others are ignored
// Publishes:
//   camera_events      msg::CameraEvent      entered = true at the first frame the robot's marker
//                                            is seen after being absent; entered = false at the
//                                            leave_after_misses-th consecutive frame without it,
//                                            or when the source fails / finishes while in view
//   camera_detections  msg::MarkerDetection  while in view, one per frame: detected = true with
//                                            (u, v) = the marker centre [px], markerId and the 4
//                                            corners [px, ArUco order]; detected = false (markerId
//                                            -1, no corners) on a missed frame not yet a leave
// Grabbed frames are stamped with the runtime clock at grab time (ctx.now()), topic frames with
// their image's stamp; frame id "camera_<id>"; pixels in OpenCV's convention ((u, v) = (column,
// row), integers at pixel centres). A frame's event comes before its detection. Markers of other
// ids are counted and ignored; while the robot's marker is tracked (detector.track_margin > 0)
// only the window around it is searched, so others elsewhere in the image are not counted then.
//
// Frames: a timer at `fps` grabs one frame (live sources are asked for a one-frame buffer, so it
// is recent where the backend honours that). A folder is read in file-name order (.png .jpg .jpeg
// .pgm .bmp, as grey), one image per tick, so its stamps are 1/fps apart; an image that cannot be
// decoded is counted as a read failure and skipped. Opening a network source may block this
// actor's handler for the backend's timeout.
//
// Topic frames are handled as they arrive; `fps` is then the rate the publisher sends them at.
// A publisher may stop sending a camera's frames (the simulator renders only cameras near the
// robot), so frames that do not come count as misses: while in view, a timer at `fps` publishes
// the leave once leave_after_misses frame periods have passed since the last frame without a
// leave (stamped where the leave_after_misses-th missing frame was due; it fires one period
// later, leaving time for frames on their way; the runtime clock is compared with the image
// stamps, so they must share it, as the simulator's do). A frame not newer than the last one
// handled (or than such a leave) is counted as late and skipped, so stamps never go back.
//
// Failures never stop the run: a source that cannot be opened, or whose read fails, is reported
// once per outage on stderr and retried after retry_initial_s, doubling up to retry_max_s. The end
// of a video file or folder (loop_folder = false) is reported once and not retried; with
// loop_folder both start again at their first frame. Errors: bad options -> ConfigError naming
// the option (constructor); an existing folder without images -> std::runtime_error naming the
// folder from start(). A topic image that cannot be read (unknown encoding, short data) is a read
// failure, reported once per run of them.
//
// Summary: frames, detections, misses, other_markers, events, open_failures, reconnects,
// read_failures, source_finished (0/1); for a topic source also late_frames and
// leaves_without_frames (leaves published by the timer because frames stopped coming).
#pragma once

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/image.capnp.h>
#include <tessera/camera_network/marker_detector.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::camera_network {

struct MarkerCameraOptions {
  int camera_id = 0;
  std::string source;
  double fps = 10.0;
  int marker_id = 7;
  double pixel_std = 1.0;
  MarkerDetectorOptions detector;
  int leave_after_misses = 5;
  double retry_initial_s = 1.0;
  double retry_max_s = 30.0;
  bool loop_folder = false;
  int image_queue = 16;

  template <class V>
  void visit(V& v) {
    v("camera_id", camera_id, "this camera's id (messages carry it; frame id camera_<id>)");
    v("source", source,
      "required: a V4L2 device (/dev/video0) or camera index (0), an RTSP/HTTP URL, a video file, "
      "a folder of images read in name order, or topic:NAME (msg::Image messages on topic NAME "
      "with frame id camera_<camera_id>, e.g. the simulated camera_network's camera_images)");
    v("fps", fps,
      "frames grabbed per second [Hz]; for a folder also the stamp spacing; for a topic the rate "
      "its frames come at (frames that stop coming count as misses)");
    v("marker_id", marker_id, "ArUco id of the robot's marker; other ids are counted and ignored");
    v("pixel_std", pixel_std, "1-sigma pixel noise written into each detection [px]");
    v("detector", detector, "ArUco marker detector");
    v("leave_after_misses", leave_after_misses,
      "consecutive frames without the marker before a leave event");
    v("retry_initial_s", retry_initial_s, "first reconnect delay after a source failure [s]");
    v("retry_max_s", retry_max_s, "reconnect delays double up to this [s]");
    v("loop_folder", loop_folder,
      "start a folder (or video file) again at its first frame instead of finishing");
    v("image_queue", image_queue,
      "topic source: images waiting (keep-latest; every camera's images arrive here)");
  }
};

class MarkerCameraActor final : public Actor {
 public:
  /// Throws ConfigError naming the option.
  explicit MarkerCameraActor(MarkerCameraOptions options);
  ~MarkerCameraActor() override;
  void configure(ActorContext& ctx) override;
  /// Opens the source (a failure schedules a retry); throws std::runtime_error for a folder
  /// without images.
  void start() override;
  void summarize(Summary& out) const override;

 private:
  struct Source;
  void tick();
  void tryOpen();
  void sourceFailed(const std::string& what, bool finished);
  void onImage(const Message<msg::Image>& m);
  void checkSilence();
  void skipFrame(const std::string& why);
  void processFrame(const cv::Mat& image, Nanos stamp);
  void publishEvent(bool entered, Nanos stamp);
  void publishDetection(const DetectedMarker* marker, Nanos stamp);

  MarkerCameraOptions options_;
  MarkerDetector detector_;
  std::unique_ptr<Source> source_;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::MarkerDetection> detection_pub_;
  Publisher<msg::CameraEvent> event_pub_;
  std::string frame_id_;
  std::string topic_;                ///< the image topic of a "topic:NAME" source; empty otherwise
  Nanos period_ = 0;                 ///< 1 / fps
  std::optional<Nanos> last_stamp_;  ///< topic source: the last frame handled (or silent leave)
  bool open_ = false, finished_ = false, in_outage_ = false, in_view_ = false;
  bool skipping_ = false;  ///< the last frame was unreadable (logged once per run of them)
  double retry_delay_s_ = 0;
  int misses_in_row_ = 0;
  std::int64_t frames_ = 0, detections_ = 0, misses_ = 0, other_markers_ = 0, events_ = 0,
               open_failures_ = 0, reconnects_ = 0, read_failures_ = 0, late_frames_ = 0,
               silent_leaves_ = 0;
};

}  // namespace tessera::camera_network
