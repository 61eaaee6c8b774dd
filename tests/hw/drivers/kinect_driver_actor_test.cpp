// The kinect driver through libfreenect's own player (Debian's fakenect library) on a synthetic
// recording, in a real runtime on the wall clock: every frame pair arrives with its colour
// unchanged and its depth converted to millimetres; the run ends with the recording. Without a
// device or a library it reports why and never crashes.
#include <tessera/drivers/fakenect_recording.hpp>
#include <tessera/drivers/kinect_driver_actor.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/runtime.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <mutex>
#include <thread>

namespace kinect_driver_actor_test {

using namespace tessera;
using namespace tessera::drivers;
namespace fs = std::filesystem;

class Listener final : public Actor {
 public:
  void configure(ActorContext& ctx) override {
    ctx.subscribe<msg::RgbdFrame>(
        "rgbd", MailboxPolicy::reliable(1000), [this](const Message<msg::RgbdFrame>& m) {
          std::lock_guard lock(mutex);
          ++frames;
          registered = m->getColorRegistered();
          fx = m->getIntrinsics().getFx();
          worst_offset_s = std::max(worst_offset_s, std::abs(m->getDepthTimeOffsetS()));
          const auto c = m->getColor().getData();
          const auto d = m->getDepth().getData();
          color_ok = color_ok && c.size() == 640 * 480 * 3 && c[0] == (frames_seen_first() & 0xff);
          std::uint16_t px[2];
          std::memcpy(&px[0], d.begin() + 2 * (240 * 640 + 100), 2);  // the far wall
          std::memcpy(&px[1], d.begin() + 2 * (240 * 640 + 320), 2);  // the near box
          wall_mm = px[0];
          box_mm = px[1];
          std::memcpy(&px[0], d.begin(), 2);  // no reading
          hole_mm = px[0];
          encodings = std::string(m->getColor().getEncoding().cStr()) + "/" +
                      m->getDepth().getEncoding().cStr();
        });
  }
  // Colour frame k is filled with k; the first one the driver pairs is 0.
  int frames_seen_first() const { return frames - 1; }
  std::mutex mutex;
  int frames = 0;
  bool registered = true, color_ok = true;
  double fx = 0;
  double worst_offset_s = 0;  ///< the largest |depth time - colour time| of a pair
  int wall_mm = -1, box_mm = -1, hole_mm = -1;
  std::string encodings;
};

constexpr int kFrames = 20;

/// A recording of kFrames pairs: colour taken 2 ms after its depth (the device's counter) and
/// reaching the host `color_late_s` after it. With `lead_in`, a lone depth frame comes 0.1 s
/// before them (fakenect plays its first entry at once, so only entries after it keep their
/// recorded lateness).
fs::path writeRecording(const std::string& name, const KinectDepthModel& model,
                        double color_late_s = 0.002, bool lead_in = false) {
  const auto folder = fs::temp_directory_path() / ("tessera_kinect_" + name);
  fs::remove_all(folder);
  FakenectRecordingWriter w(folder);
  std::vector<std::uint16_t> depth(640 * 480);
  for (int v = 0; v < 480; ++v)
    for (int u = 0; u < 640; ++u) {
      const bool box = u >= 270 && u < 370 && v >= 190 && v < 290;
      depth[static_cast<std::size_t>(v * 640 + u)] =
          static_cast<std::uint16_t>(model.disparity(box ? 0.8 : 3.0));
    }
  depth[0] = KinectDepthModel::kNoReading;
  const auto ticks = [](double s) { return static_cast<std::uint32_t>(std::llround(s * 60e6)); };
  if (lead_in) w.addDepth(0, 0, depth);
  for (int k = 0; k < kFrames; ++k) {
    const double t = (lead_in ? 0.1 : 0.0) + k / 30.0;
    w.addDepth(t, ticks(t), depth);
    w.addColor(t + color_late_s, ticks(t + 0.002),
               std::vector<std::uint8_t>(640 * 480 * 3, static_cast<std::uint8_t>(k)));
  }
  return folder;
}

/// Runs the driver and a listener for at most `max_s`, then `check`s (the listener lives as long
/// as the runtime).
void runFor(KinectActorOptions o, double max_s,
            const std::function<void(const RunReport&, Listener&)>& check) {
  RuntimeOptions ro;
  ro.clock = ClockKind::kWall;
  ro.threads = 2;
  ro.show_progress = false;
  Runtime rt(ro);
  rt.add("camera", std::make_unique<KinectDriverActor>(std::move(o)));
  auto& listener = static_cast<Listener&>(rt.add("listener", std::make_unique<Listener>()));
  // A driver is no finite source (unless it plays a recording): stop the run after max_s.
  std::atomic<bool> done{false};
  RunReport report;
  std::thread runner([&] {
    report = rt.run();
    done = true;
  });
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(max_s);
  while (!done && std::chrono::steady_clock::now() < end)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  if (!done) rt.requestStop();
  runner.join();
  check(report, listener);
}

// First: it loads the system's libfreenect by name, which a fakenect loaded before would
// answer in the same process (ctest runs each case alone).
TEST_CASE("kinect without a device keeps retrying with back-off and publishes nothing",
          "[drivers][kinect]") {
  // The system's libfreenect on a machine without a Kinect (or without USB access).
  KinectActorOptions o;
  o.retry_initial_s = 0.05;
  o.retry_max_s = 0.2;
  runFor(o, 1.0, [](const RunReport& report, Listener& l) {
    const auto& s = report.actors.at(0).summary;
    INFO(std::get<std::string>(s.at("last_error")));
    CHECK(std::get<std::int64_t>(s.at("open_failures")) >= 2);
    CHECK(std::get<std::int64_t>(s.at("frames")) == 0);
    CHECK(l.frames == 0);
    CHECK_THAT(std::get<std::string>(s.at("last_error")),
               Catch::Contains("no Kinect") || Catch::Contains("freenect_init"));
  });
}

TEST_CASE("kinect plays a fakenect recording: colour as sent, raw depth in millimetres",
          "[drivers][kinect]") {
  KinectActorOptions o;
  o.recording = writeRecording("play", o.depth).string();
  o.registration = "none";
  const auto t0 = std::chrono::steady_clock::now();
  const std::string folder = o.recording;
  runFor(o, 20, [&](const RunReport& report, Listener& l) {
    const double wall =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    fs::remove_all(folder);
    INFO(report.table());
    // The run ended with the recording, played at its own pace (19 gaps of 1/30 s).
    CHECK_FALSE(report.interrupted);
    CHECK(wall >= 0.55);
    CHECK(wall < 15);
    std::lock_guard lock(l.mutex);
    CHECK(l.frames == kFrames);
    CHECK(l.color_ok);
    CHECK_FALSE(l.registered);
    CHECK(l.fx == 585);  // the IR camera's intrinsics: the depth is in that camera
    CHECK(l.encodings == "rgb8/16UC1");
    CHECK_THAT(l.worst_offset_s, Catch::WithinAbs(0.002, 1e-4));
    // One disparity step at 3 m is 26 mm; at 0.8 m under 2 mm.
    CHECK(std::abs(l.wall_mm - 3000) <= 13);
    CHECK(std::abs(l.box_mm - 800) <= 1);
    CHECK(l.hole_mm == 0);
    const auto& s = report.actors.at(0).summary;
    CHECK(std::get<std::int64_t>(s.at("frames")) == kFrames);
    CHECK(std::get<std::int64_t>(s.at("dropped_unpaired")) == 0);
    CHECK(std::get<double>(s.at("latency_ms_max")) < 100);
  });
}

// Both streams carry the one device counter: how late a frame reaches the host (a busy host, a
// slow USB transfer) must not decide whether it pairs. Colour here arrives 25 ms after its
// depth, beyond max_pair_gap_s, though taken 2 ms after it.
TEST_CASE("kinect pairs by the device's counter: colour that reaches the host late still pairs",
          "[drivers][kinect]") {
  KinectActorOptions o;
  o.recording = writeRecording("late_color", o.depth, 0.025, true).string();
  o.registration = "none";
  REQUIRE(o.max_pair_gap_s < 0.025);
  const std::string folder = o.recording;
  runFor(o, 20, [&](const RunReport& report, Listener& l) {
    fs::remove_all(folder);
    INFO(report.table());
    CHECK_FALSE(report.interrupted);
    std::lock_guard lock(l.mutex);
    CHECK(l.frames == kFrames);
    CHECK(l.color_ok);
    const auto& s = report.actors.at(0).summary;
    // Each colour frame with its own depth, taken 2 ms before it, not with the next one.
    CHECK_THAT(l.worst_offset_s, Catch::WithinAbs(0.002, 1e-4));
    CHECK(std::get<std::int64_t>(s.at("dropped_unpaired")) == 1);  // the lead-in
  });
}

TEST_CASE("kinect refuses a broken recording or a registration fakenect cannot play",
          "[drivers][kinect]") {
  KinectActorOptions o;
  o.recording = writeRecording("broken", o.depth).string();
  o.registration = "device";
  CHECK_THROWS_WITH(KinectDriverActor(o), Catch::Contains("registration"));
  o.registration = "none";
  fs::resize_file(fs::path(o.recording) / "INDEX.txt", 0);
  CHECK_THROWS_WITH(KinectDriverActor(o), Catch::Contains("both streams"));
  fs::remove_all(o.recording);
  o.recording = "/nonexistent/recording";
  CHECK_THROWS_WITH(KinectDriverActor(o), Catch::Contains("INDEX.txt"));
  o = {};
  o.depth_camera = {585, 585, 320};
  CHECK_THROWS_WITH(KinectDriverActor(o), Catch::Contains("depth_camera"));
  o = {};
  o.registration = "sometimes";
  CHECK_THROWS_WITH(KinectDriverActor(o), Catch::Contains("device or none"));
}

TEST_CASE("kinect without its library stops the run saying what to install", "[drivers][kinect]") {
  KinectActorOptions o;
  o.library = "/nonexistent/libfreenect.so.0.5";
  runFor(o, 10, [](const RunReport& report, Listener&) {
    CHECK(report.interrupted);
    CHECK_THAT(report.stop_reason,
               Catch::Contains("cannot load") && Catch::Contains("libfreenect"));
  });
}

}  // namespace kinect_driver_actor_test
