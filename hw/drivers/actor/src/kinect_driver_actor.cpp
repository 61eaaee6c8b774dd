#include <tessera/drivers/kinect_driver_actor.hpp>

#include <tessera/drivers/device_loop.hpp>
#include <tessera/drivers/fakenect_recording.hpp>
#include <tessera/drivers/freenect_camera.hpp>
#include <tessera/drivers/sensor_clock.hpp>
#include <tessera/drivers/session_text.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <span>

#ifndef TESSERA_FAKENECT_LIBRARY
#define TESSERA_FAKENECT_LIBRARY ""
#endif

namespace tessera::drivers {

namespace kinect_actor_detail {

[[noreturn]] void fail(const std::string& key, const std::string& what) {
  throw ConfigError("kinect: option '" + key + "': " + what);
}

void checkCamera(const std::string& key, const std::vector<double>& k) {
  if (k.size() != 4)
    fail(key, "needs [fx, fy, cx, cy], got " + std::to_string(k.size()) + " values");
  for (const double v : k)
    if (!std::isfinite(v) || v <= 0) fail(key, "values must be finite and > 0, got " + decimal(v));
}

KinectDepthConverter checkedConverter(const KinectActorOptions& o) {
  try {
    return KinectDepthConverter(o.depth, 1000.0);
  } catch (const std::invalid_argument& e) {
    fail("depth", e.what());
  }
}

void writeImage(msg::Image::Builder b, Nanos stamp, const std::string& frame, std::uint64_t seq,
                const char* encoding, std::uint32_t bytes_per_pixel) {
  setHeader(b.initHeader(), stamp, frame, seq);
  b.setWidth(kKinectWidth);
  b.setHeight(kKinectHeight);
  b.setEncoding(encoding);
  b.setStep(kKinectWidth * bytes_per_pixel);
}

}  // namespace kinect_actor_detail

KinectDriverActor::KinectDriverActor(KinectActorOptions options)
    : options_(std::move(options)), converter_(kinect_actor_detail::checkedConverter(options_)) {
  namespace d = kinect_actor_detail;
  const auto& o = options_;
  if (o.registration == "device")
    registered_ = true;
  else if (o.registration != "none")
    d::fail("registration", "is '" + o.registration + "', expected device or none");
  if (o.device_index < 0) d::fail("device_index", "must be >= 0");
  if (o.frame_id.empty()) d::fail("frame_id", "must not be empty");
  if (!(o.max_pair_gap_s > 0) || !std::isfinite(o.max_pair_gap_s))
    d::fail("max_pair_gap_s", "must be finite and > 0, got " + decimal(o.max_pair_gap_s));
  d::checkCamera("depth_camera", o.depth_camera);
  d::checkCamera("color_camera", o.color_camera);
  if (!(o.retry_initial_s > 0) || !(o.retry_max_s >= o.retry_initial_s) ||
      !std::isfinite(o.retry_max_s))
    d::fail("retry_initial_s", "needs 0 < retry_initial_s <= retry_max_s (finite)");
  library_ = o.library.empty() ? std::string("libfreenect.so.0.5") : o.library;
  if (!o.recording.empty()) {
    if (registered_)
      d::fail("registration",
              "must be none with a recording: fakenect plays the raw depth only (registration "
              "needs the calibration a real Kinect stores)");
    try {
      checkFakenectRecording(o.recording);
    } catch (const FakenectRecordingError& e) {
      d::fail("recording", e.what());
    }
    if (o.library.empty()) {
      library_ = TESSERA_FAKENECT_LIBRARY;
      if (library_.empty() || !std::filesystem::exists(library_))
        d::fail("recording",
                "needs Debian's fakenect library (package libfreenect0.5, "
                "/usr/lib/<arch>/fakenect/), not found at build time; give its path as 'library'");
    }
  }
}

KinectDriverActor::~KinectDriverActor() {
  stop();
}

void KinectDriverActor::configure(ActorContext& ctx) {
  requireWallClock("kinect", ctx);
  ctx_ = &ctx;
  rgbd_pub_ = ctx.advertise<msg::RgbdFrame>("rgbd");
  if (!options_.recording.empty()) {
    ctx.declareFiniteSource();
    // The I/O thread only raises a flag: finished() belongs to the runtime's threads.
    ctx.addTimer(kNanosPerSecond / 10, [this] {
      if (ended_ && !finished_) {
        finished_ = true;
        ctx_->finished();
      }
    });
  }
}

void KinectDriverActor::start() {
  if (!options_.recording.empty()) {
    // fakenect finds its folder in the environment when it is initialised (on the I/O thread).
    const auto folder = std::filesystem::absolute(options_.recording).string();
    ::setenv("FAKENECT_PATH", folder.c_str(), 1);
  }
  thread_ = std::thread([this] { run(); });
}

void KinectDriverActor::stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

bool KinectDriverActor::waitOrStop(double seconds) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (!stop_ && std::chrono::steady_clock::now() < end)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  return stop_;
}

void KinectDriverActor::run() {
  namespace d = kinect_actor_detail;
  const std::string source = options_.recording.empty()
                                 ? "Kinect " + std::to_string(options_.device_index)
                                 : "fakenect recording " + options_.recording;
  const auto log = [&](const std::string& event) {
    std::cerr << "[kinect] " << source << ": " << event << "\n";
  };
  const auto failed = [&](const std::string& error, bool opening) {
    std::lock_guard lock(mutex_);
    last_error_ = error;
    ++(opening ? open_failures_ : reconnects_);
  };
  RgbdPairer pairer(nanosOf(options_.max_pair_gap_s));
  std::int64_t depth_count = 0, color_count = 0;
  // Both streams' frames carry the device's one 60 MHz counter: stamped by it, frames keep the
  // device's timing instead of the host's (USB, scheduling) jitter, and colour and depth pair by
  // when they were taken, however late either reached the host. One clock for both: per-stream
  // offsets would differ by how much later one stream arrives, which would decide the pairing.
  // The host may get a frame after a later-taken one of the other stream: up to a second back
  // is earlier, not a wrap.
  constexpr std::int64_t kKinectTicksPerSecond = 60'000'000;
  SensorClock device_clock = SensorClock::withTickRate(32, kKinectTicksPerSecond);
  device_clock.allowBackSteps(kKinectTicksPerSecond);
  constexpr std::size_t kPixels = std::size_t{kKinectWidth} * kKinectHeight;
  // Frames are copied out of libfreenect's buffer (valid only during the callback) into what
  // is published: colour as it is, depth converted to millimetres on the way. The buffers of a
  // published pair are used again: fresh 1 MB buffers cost page faults (measured: 0.5 ms a
  // frame of the latency).
  KinectImage spare_color, spare_depth;
  const auto recycle = [&](RgbdPairer::Pair&& p) {
    spare_color = std::move(p.color);
    spare_depth = std::move(p.depth);
  };
  const auto colorImage = [&](const void* data, std::size_t bytes, std::uint32_t timestamp) {
    KinectImage im = std::move(spare_color);
    im.bytes.clear();
    im.stamp_ns = device_clock.stamp(timestamp, ctx_->now());
    if (bytes >= kPixels * 3)
      im.bytes.assign(static_cast<const std::uint8_t*>(data),
                      static_cast<const std::uint8_t*>(data) + kPixels * 3);
    return im;
  };
  const auto depthImage = [&](const void* data, std::size_t bytes, std::uint32_t timestamp) {
    KinectImage im = std::move(spare_depth);
    im.depth.clear();
    im.stamp_ns = device_clock.stamp(timestamp, ctx_->now());
    if (bytes < kPixels * 2) return im;
    im.depth.resize(kPixels);
    if (registered_) {
      std::memcpy(im.depth.data(), data, kPixels * 2);  // libfreenect's millimetres
    } else {
      const std::size_t corrupt = converter_.convert(
          std::span<const std::uint16_t>(static_cast<const std::uint16_t*>(data), kPixels),
          im.depth);
      if (corrupt > 0) {
        std::lock_guard lock(mutex_);
        corrupt_pixels_ += static_cast<std::int64_t>(corrupt);
      }
    }
    return im;
  };
  std::unique_ptr<FreenectCamera> camera;
  try {
    camera = std::make_unique<FreenectCamera>(
        FreenectCameraOptions{library_, options_.device_index, registered_},
        [&](const void* data, std::size_t bytes, std::uint32_t timestamp) {
          const auto t0 = std::chrono::steady_clock::now();
          ++depth_count;
          if (auto p = pairer.addDepth(depthImage(data, bytes, timestamp))) {
            publish(*p, t0);
            recycle(std::move(*p));
          }
        },
        [&](const void* data, std::size_t bytes, std::uint32_t timestamp) {
          const auto t0 = std::chrono::steady_clock::now();
          ++color_count;
          if (auto p = pairer.addColor(colorImage(data, bytes, timestamp))) {
            publish(*p, t0);
            recycle(std::move(*p));
          }
        });
  } catch (const FreenectError& e) {
    failed(e.what(), true);
    log(std::string(e.what()) + "; the driver publishes nothing");
    ctx_->requestStop(std::string("kinect: ") + e.what());
    return;
  }
  double delay = options_.retry_initial_s;
  bool in_outage = false;
  auto last_cpu = std::chrono::steady_clock::now();
  while (!stop_) {
    try {
      camera->open();
    } catch (const FreenectError& e) {
      failed(e.what(), true);
      if (!in_outage)
        log(std::string(e.what()) + "; retrying every " + decimal(delay) + " s and up to " +
            decimal(options_.retry_max_s) + " s");
      in_outage = true;
      if (waitOrStop(delay)) break;
      delay = std::min(2 * delay, options_.retry_max_s);
      continue;
    }
    log("streaming 640 x 480 colour and " +
        std::string(registered_ ? "registered depth" : "raw depth"));
    in_outage = false;
    const std::int64_t frames_at_open = depth_count + color_count;
    bool alive = true;
    while (!stop_ && (alive = camera->processEvents(100))) {
      const auto now = std::chrono::steady_clock::now();
      if (now - last_cpu > std::chrono::seconds(1)) {
        last_cpu = now;
        std::lock_guard lock(mutex_);
        cpu_s_ = threadCpuSeconds();
        depth_frames_ = depth_count;
        color_frames_ = color_count;
        dropped_ = pairer.dropped();
      }
    }
    {
      std::lock_guard lock(mutex_);
      depth_frames_ = depth_count;
      color_frames_ = color_count;
      dropped_ = pairer.dropped();
    }
    camera->close();
    pairer.reset();
    device_clock.reset();  // a Kinect plugged in again starts its counter anew
    if (stop_) break;
    if (!options_.recording.empty()) {
      if (depth_count + color_count == 0) {
        // fakenect keeps its place in a recording for the whole process.
        const std::string why =
            "fakenect played no frame: a process plays one recording, once (run it in its own "
            "process)";
        failed(why, true);
        log(why);
        ctx_->requestStop("kinect: " + why);
        break;
      }
      log("the recording has been played to its end (" + std::to_string(frames_) + " frames)");
      ended_ = true;
      break;
    }
    if (!alive) {
      failed("the Kinect stopped answering (unplugged?)", false);
      if (depth_count + color_count > frames_at_open) delay = options_.retry_initial_s;
      log("the Kinect stopped answering (unplugged?); reopening in " + decimal(delay) + " s");
      in_outage = true;
      if (waitOrStop(delay)) break;
      delay = std::min(2 * delay, options_.retry_max_s);
    }
  }
  std::lock_guard lock(mutex_);
  cpu_s_ = threadCpuSeconds();
}

void KinectDriverActor::publish(const RgbdPairer::Pair& pair,
                                std::chrono::steady_clock::time_point t0) {
  namespace d = kinect_actor_detail;
  constexpr std::size_t kPixels = std::size_t{kKinectWidth} * kKinectHeight;
  if (pair.color.bytes.size() < kPixels * 3 || pair.depth.depth.size() < kPixels) {
    std::lock_guard lock(mutex_);
    last_error_ = "a frame shorter than 640 x 480 (dropped)";
    return;
  }
  const Nanos stamp = pair.color.stamp_ns;
  auto loan = rgbd_pub_.loan(kPixels * 5 + 1024);
  auto b = loan.builder();
  const std::uint64_t seq = rgbd_pub_.nextSeq();
  setHeader(b.initHeader(), stamp, options_.frame_id, seq);
  const auto& k = registered_ ? options_.color_camera : options_.depth_camera;
  auto in = b.initIntrinsics();
  in.setFx(k[0]);
  in.setFy(k[1]);
  in.setCx(k[2]);
  in.setCy(k[3]);
  in.setWidth(kKinectWidth);
  in.setHeight(kKinectHeight);
  b.setDepthScale(1000.0);
  b.setColorRegistered(registered_);
  b.setHasGroundTruth(false);
  b.setDatasetTimeS(static_cast<double>(stamp) * 1e-9);
  b.setDepthTimeOffsetS(static_cast<double>(pair.depth.stamp_ns - stamp) * 1e-9);
  std::int64_t index = 0;
  {
    std::lock_guard lock(mutex_);
    index = frames_;
  }
  b.setFrameIndex(static_cast<std::uint32_t>(index));
  auto color = b.initColor();
  auto depth = b.initDepth();
  d::writeImage(color, stamp, options_.frame_id, seq, "rgb8", 3);
  d::writeImage(depth, pair.depth.stamp_ns, options_.frame_id, seq, "16UC1", 2);
  auto color_data = color.initData(static_cast<unsigned>(kPixels * 3));
  std::memcpy(color_data.begin(), pair.color.bytes.data(), kPixels * 3);
  auto depth_data = depth.initData(static_cast<unsigned>(kPixels * 2));
  std::memcpy(depth_data.begin(), pair.depth.depth.data(), kPixels * 2);
  rgbd_pub_.publish(std::move(loan));
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  std::lock_guard lock(mutex_);
  ++frames_;
  if (latencies_ms_.size() < 100000) latencies_ms_.push_back(ms);
}

void KinectDriverActor::summarize(Summary& out) const {
  std::lock_guard lock(mutex_);
  out["frames"] = frames_;
  out["depth_frames"] = depth_frames_;
  out["color_frames"] = color_frames_;
  out["dropped_unpaired"] = dropped_;
  out["corrupt_depth_pixels"] = corrupt_pixels_;
  out["reconnects"] = reconnects_;
  out["open_failures"] = open_failures_;
  out["last_error"] = last_error_;
  out["cpu_s"] = cpu_s_;
  std::vector<double> l = latencies_ms_;
  double median = 0, p99 = 0, max = 0;
  if (!l.empty()) {
    std::sort(l.begin(), l.end());
    median = l[l.size() / 2];
    p99 = l[std::min(l.size() - 1, l.size() * 99 / 100)];
    max = l.back();
  }
  out["latency_ms_median"] = median;
  out["latency_ms_p99"] = p99;
  out["latency_ms_max"] = max;
  out["registration"] = options_.registration;
}

TESSERA_REGISTER_ACTOR("kinect", KinectDriverActor, KinectActorOptions,
                       "Kinect v1 through libfreenect (or a fakenect recording): paired colour and "
                       "depth frames");

}  // namespace tessera::drivers
