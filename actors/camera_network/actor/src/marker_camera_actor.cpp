#include <tessera/camera_network/marker_camera_actor.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/registry.hpp>

#include <tessera/camera_network/video_source.hpp>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <system_error>

namespace tessera::camera_network {

namespace marker_camera_detail {

namespace fs = std::filesystem;

constexpr std::string_view kTopicPrefix = "topic:";

/// The topic of a "topic:NAME" source, or "" for any other source.
std::string topicOf(const std::string& source) {
  return source.starts_with(kTopicPrefix) ? source.substr(kTopicPrefix.size()) : std::string();
}

void require(bool ok, const char* key, const std::string& rule) {
  if (!ok) throw ConfigError(std::string("marker_camera: ") + key + " " + rule);
}

MarkerCameraOptions checked(MarkerCameraOptions o) {
  require(!o.source.empty(), "source",
          "is required (a device, camera index, URL, video file or image folder)");
  require(o.source != kTopicPrefix, "source", "'topic:' needs a topic name (topic:NAME)");
  require(o.camera_id >= 0, "camera_id", "must be >= 0");
  require(std::isfinite(o.fps) && o.fps > 0 && o.fps <= 1000, "fps", "must be in (0, 1000] Hz");
  require(o.marker_id >= 0, "marker_id", "must be >= 0");
  require(std::isfinite(o.pixel_std) && o.pixel_std > 0, "pixel_std", "must be finite and > 0");
  require(o.leave_after_misses >= 1, "leave_after_misses", "must be >= 1");
  require(std::isfinite(o.retry_initial_s) && o.retry_initial_s > 0, "retry_initial_s",
          "must be finite and > 0");
  require(std::isfinite(o.retry_max_s) && o.retry_max_s >= o.retry_initial_s, "retry_max_s",
          "must be finite and >= retry_initial_s");
  require(o.image_queue >= 1, "image_queue", "must be >= 1");
  return o;
}

MarkerDetector detectorFor(const MarkerDetectorOptions& o) {
  try {
    return MarkerDetector(o);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(std::string("marker_camera: detector: ") + e.what());
  }
}

Nanos toNanos(double seconds) {
  return std::max<Nanos>(1, static_cast<Nanos>(std::llround(std::min(seconds, 1e9) * 1e9)));
}

bool isUrl(const std::string& s) {
  return s.find("://") != std::string::npos;
}

bool isImageFile(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".pgm" || ext == ".bmp";
}

/// The image files of `dir`, sorted by name.
std::vector<fs::path> listImages(const fs::path& dir) {
  std::vector<fs::path> files;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->is_regular_file(ec) && isImageFile(it->path())) files.push_back(it->path());
  std::sort(files.begin(), files.end());
  return files;
}

/// The pixels of an image message as a Mat (grey or BGR, over the message's bytes where the
/// detector takes them as they are; rgb8 is converted to grey in `converted`), or an empty Mat
/// with the reason in `error`.
cv::Mat pixelsOf(msg::Image::Reader im, cv::Mat& converted, std::string& error) {
  const std::string_view encoding(im.getEncoding().cStr());
  int type = 0;
  if (encoding == "mono8") {
    type = CV_8UC1;
  } else if (encoding == "bgr8" || encoding == "rgb8") {
    type = CV_8UC3;
  } else {
    error = "encoding '" + std::string(encoding) + "' (expected mono8, bgr8 or rgb8)";
    return {};
  }
  const std::size_t w = im.getWidth(), h = im.getHeight(), step = im.getStep();
  const std::size_t bpp = type == CV_8UC1 ? 1 : 3;
  if (w == 0 || h == 0 || w > 1u << 15 || h > 1u << 15) {
    error = "image size " + std::to_string(w) + " x " + std::to_string(h);
    return {};
  }
  if (step < w * bpp || im.getData().size() < h * step) {
    error = "pixel data shorter than height x step";
    return {};
  }
  // The detector only reads the pixels, and the message outlives the call.
  auto* data = const_cast<std::uint8_t*>(im.getData().begin());
  const cv::Mat pixels(static_cast<int>(h), static_cast<int>(w), type, data, step);
  if (encoding != "rgb8") return pixels;
  cv::cvtColor(pixels, converted, cv::COLOR_RGB2GRAY);
  return converted;
}

std::string seconds(double s) {
  std::ostringstream out;
  out << s;
  return out.str();
}

}  // namespace marker_camera_detail

/// The open source: a folder's image list, or a VideoSource; and the robot's marker tracked
/// through its frames (a new source starts with a whole-image search).
struct MarkerCameraActor::Source {
  bool folder = false;
  bool file = false;  ///< a video file: its end is the end of the source
  std::vector<std::filesystem::path> images;
  std::size_t next = 0;
  std::unique_ptr<VideoSource> capture;  ///< null when closed
  std::optional<MarkerTracker> tracker;
};

MarkerCameraActor::MarkerCameraActor(MarkerCameraOptions options)
    : options_(marker_camera_detail::checked(std::move(options))),
      detector_(marker_camera_detail::detectorFor(options_.detector)),
      source_(std::make_unique<Source>()),
      frame_id_("camera_" + std::to_string(options_.camera_id)),
      topic_(marker_camera_detail::topicOf(options_.source)),
      period_(marker_camera_detail::toNanos(1.0 / options_.fps)),
      retry_delay_s_(options_.retry_initial_s) {}

MarkerCameraActor::~MarkerCameraActor() = default;

void MarkerCameraActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  event_pub_ = ctx.advertise<msg::CameraEvent>("camera_events");
  detection_pub_ = ctx.advertise<msg::MarkerDetection>("camera_detections");
  if (!topic_.empty()) {
    ctx.subscribe<msg::Image>(
        topic_, MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.image_queue)),
        [this](const Message<msg::Image>& m) { onImage(m); });
    ctx.addTimer(period_, [this] { checkSilence(); });
    return;
  }
  ctx.addTimer(period_, [this] { tick(); });
}

void MarkerCameraActor::start() {
  namespace fs = std::filesystem;
  if (!topic_.empty()) return;  // frames come by themselves
  std::error_code ec;
  const fs::path path(options_.source);
  if (fs::is_directory(path, ec) && marker_camera_detail::listImages(path).empty())
    throw std::runtime_error("marker_camera: camera " + std::to_string(options_.camera_id) +
                             ": folder '" + options_.source +
                             "' holds no images (.png .jpg .jpeg .pgm .bmp)");
  tryOpen();
}

void MarkerCameraActor::tryOpen() {
  namespace fs = std::filesystem;
  namespace mcd = marker_camera_detail;
  if (open_ || finished_) return;
  source_ = std::make_unique<Source>();
  Source& s = *source_;
  const std::string& src = options_.source;
  std::error_code ec;
  std::string reason = "cannot be opened";
  if (fs::is_directory(src, ec)) {
    s.folder = true;
    s.images = mcd::listImages(src);
    open_ = !s.images.empty();
    if (!open_) reason = "holds no images";
  } else if (!VideoSource::isDeviceIndex(src) && !mcd::isUrl(src) && !fs::exists(src, ec)) {
    reason = "cannot be opened (no such file, folder or device)";  // spares OpenCV's warnings
  } else {
    s.file = fs::is_regular_file(src, ec);
    try {
      s.capture = VideoSource::open(src, /*live=*/!s.file);
      open_ = true;
    } catch (const std::runtime_error& e) {
      open_ = false;
      reason = e.what();
    }
  }

  if (open_) {
    if (in_outage_) {
      ++reconnects_;
      std::cerr << "[marker_camera] camera " << options_.camera_id << ": " << src
                << " reconnected\n";
    }
    in_outage_ = false;
    retry_delay_s_ = options_.retry_initial_s;
    return;
  }
  ++open_failures_;
  s.capture.reset();
  sourceFailed(reason, /*finished=*/false);
}

void MarkerCameraActor::sourceFailed(const std::string& what, bool finished) {
  open_ = false;
  if (in_view_) publishEvent(false, ctx_->now());  // the camera sees nothing any more
  if (finished) {
    finished_ = true;
    std::cerr << "[marker_camera] camera " << options_.camera_id << ": " << options_.source << " "
              << what << " after " << frames_ << " frames\n";
    return;
  }
  if (!in_outage_) {
    std::cerr << "[marker_camera] camera " << options_.camera_id << ": " << options_.source << " "
              << what << "; retrying in " << marker_camera_detail::seconds(retry_delay_s_)
              << " s\n";
    in_outage_ = true;
  }
  ctx_->callAt(ctx_->now() + marker_camera_detail::toNanos(retry_delay_s_), [this] { tryOpen(); });
  retry_delay_s_ = std::min(2 * retry_delay_s_, options_.retry_max_s);
}

void MarkerCameraActor::tick() {
  namespace mcd = marker_camera_detail;
  if (!open_) return;
  Source& s = *source_;
  cv::Mat image;
  if (s.folder) {
    if (s.next >= s.images.size()) {
      if (!options_.loop_folder) {
        sourceFailed("finished", /*finished=*/true);
        return;
      }
      s.next = 0;
    }
    const auto& file = s.images[s.next++];
    try {
      image = VideoSource::readImage(file.string());
    } catch (const std::runtime_error& e) {
      sourceFailed(e.what(), /*finished=*/true);
      return;
    }
    if (image.empty()) {
      skipFrame("cannot read " + file.string());
      return;
    }
  } else if (!s.capture || !s.capture->read(image)) {
    if (s.file && options_.loop_folder && frames_ > 0) {
      s.capture.reset();  // reopen at the first frame on the next tick
      open_ = false;
      tryOpen();
      return;
    }
    if (s.file) {
      sourceFailed("finished", /*finished=*/true);
      return;
    }
    ++read_failures_;
    s.capture.reset();
    sourceFailed("read failed", /*finished=*/false);
    return;
  }
  processFrame(image, ctx_->now());
}

void MarkerCameraActor::onImage(const Message<msg::Image>& m) {
  const auto header = m->getHeader();
  if (std::string_view(header.getFrameId().cStr()) != frame_id_) return;  // another camera's
  const Nanos stamp = header.getStampNs();
  if (last_stamp_ && stamp <= *last_stamp_) {
    ++late_frames_;
    return;
  }
  cv::Mat converted;
  std::string error;
  const cv::Mat image = marker_camera_detail::pixelsOf(*m, converted, error);
  if (image.empty()) {
    skipFrame("frame skipped: " + error);
    return;
  }
  last_stamp_ = stamp;
  processFrame(image, stamp);
}

void MarkerCameraActor::checkSilence() {
  if (!in_view_ || !last_stamp_) return;
  // The frames that did not come are misses: the leave is due where the leave_after_misses-th
  // would have been, and published one period after that, when any such frame would be here.
  const Nanos due = *last_stamp_ + (options_.leave_after_misses - misses_in_row_) * period_;
  if (ctx_->now() < due + period_) return;
  publishEvent(false, due);
  last_stamp_ = due;  // a frame from before the leave would be late now
  ++silent_leaves_;
}

void MarkerCameraActor::skipFrame(const std::string& why) {
  ++read_failures_;
  if (!skipping_)  // once per run of unreadable frames
    std::cerr << "[marker_camera] camera " << options_.camera_id << ": " << why << "\n";
  skipping_ = true;
}

void MarkerCameraActor::processFrame(const cv::Mat& image, Nanos stamp) {
  // While the robot's marker is in view, only a window around it is searched (detector
  // track_margin), so markers of other ids elsewhere in the image are counted only while it is not.
  auto& tracker = source_->tracker;
  if (!tracker) tracker.emplace(detector_, options_.marker_id);
  std::vector<DetectedMarker> markers;
  try {
    markers = tracker->detect(image);
  } catch (const std::invalid_argument& e) {  // an image type the detector does not take
    skipFrame(std::string("frame skipped: ") + e.what());
    return;
  }
  skipping_ = false;
  ++frames_;
  const DetectedMarker* robot = nullptr;
  for (const auto& m : markers) {
    if (m.id != options_.marker_id)
      ++other_markers_;
    else if (!robot)
      robot = &m;
  }
  if (robot) {
    if (!in_view_) publishEvent(true, stamp);
    misses_in_row_ = 0;
    publishDetection(robot, stamp);
    return;
  }
  if (!in_view_) return;
  if (++misses_in_row_ >= options_.leave_after_misses) {
    publishEvent(false, stamp);
    return;
  }
  publishDetection(nullptr, stamp);
}

void MarkerCameraActor::publishEvent(bool entered, Nanos stamp) {
  auto loan = event_pub_.loan();
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, frame_id_, event_pub_.nextSeq());
  b.setCameraId(options_.camera_id);
  b.setEntered(entered);
  event_pub_.publish(std::move(loan));
  ++events_;
  in_view_ = entered;
  misses_in_row_ = 0;
}

void MarkerCameraActor::publishDetection(const DetectedMarker* marker, Nanos stamp) {
  auto loan = detection_pub_.loan();
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, frame_id_, detection_pub_.nextSeq());
  b.setCameraId(options_.camera_id);
  b.setDetected(marker != nullptr);
  b.setPixelStd(options_.pixel_std);
  if (marker) {
    b.setU(marker->centre.x());
    b.setV(marker->centre.y());
    b.setMarkerId(marker->id);
    auto corners = b.initCorners(8);
    for (unsigned k = 0; k < 4; ++k) {
      corners.set(2 * k, marker->corners[k].x());
      corners.set(2 * k + 1, marker->corners[k].y());
    }
    ++detections_;
  } else {
    ++misses_;
  }
  detection_pub_.publish(std::move(loan));
}

void MarkerCameraActor::summarize(Summary& out) const {
  out["frames"] = frames_;
  out["detections"] = detections_;
  out["misses"] = misses_;
  out["other_markers"] = other_markers_;
  out["events"] = events_;
  out["open_failures"] = open_failures_;
  out["reconnects"] = reconnects_;
  out["read_failures"] = read_failures_;
  out["source_finished"] = std::int64_t{finished_ ? 1 : 0};
  if (!topic_.empty()) {
    out["late_frames"] = late_frames_;
    out["leaves_without_frames"] = silent_leaves_;
  }
}

TESSERA_REGISTER_ACTOR("marker_camera", MarkerCameraActor, MarkerCameraOptions,
                       "real environment camera (device, stream, video file, image folder or "
                       "image topic): ArUco marker detections and enter/leave events");

}  // namespace tessera::camera_network
