// `tessera bench marker_detection`: the ArUco marker detector (camera_network/marker_detector.hpp)
// on rendered ceiling-camera images (sim/camera_image.hpp) of the seed-000 camera floor's seven
// cameras (640 x 480, focal 320 px, 3 m above the marker, the renderer's default 1 px blur and
// noise of 2 grey levels), the robot's marker (DICT_4X4_50 id 7, 0.2 m) in view. Two modes:
//   full      every frame its own random in-view pose, searched whole (MarkerDetector::detect);
//   tracking  the robot driving through each camera's view in turn at 0.3 m/s, a frame every
//             0.1 s, followed by a MarkerTracker (a window around the last detection, the whole
//             image when the window misses: at every new pass, and for frames the marker only
//             partly shows in).
// Only detection is timed (rendering is not); each frame is detected --repeats times (the tracker
// restarted from the same state) and its time is the median of those. A frame counts as
// detected when id 7 is found with its centre within 2 px of the true centre; the detection rate
// and the errors are over the frames whose marker lies wholly in view.
#include "bench_commands.hpp"
#include "bench_util.hpp"

#include <tessera/camera_network/marker_detector.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/sim/camera_image.hpp>
#include <tessera/sim/camera_network.hpp>
#include <tessera/sim/world.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/core/utility.hpp>

#include <chrono>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <memory>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace tessera::app {
namespace marker_detection_bench {

using camera_network::DetectedMarker;
using camera_network::MarkerDetector;
using camera_network::MarkerDetectorOptions;
using camera_network::MarkerTracker;

struct Options {
  int frames = 400;
  int repeats = 3;
  std::string mode = "both";
  std::uint64_t seed = 1;
  MarkerDetectorOptions detector;
  bool json = false;
};

constexpr double kSpeed = 0.3;             // [m/s] the robot through a camera's view
constexpr double kFrameRate = 10.0;        // [Hz]
constexpr double kBorderPx = 6.0;          // in view: marker corners this far inside the image
constexpr double kDetectedWithinPx = 2.0;  // a detection's centre from the true centre

/// One frame to render: which camera, where the marker is.
struct Shot {
  std::size_t camera = 0;
  Pose2 pose;
  bool in_view = false;  ///< the whole marker at least kBorderPx inside the image
};

bool wholeMarkerInView(const sim::EnvironmentCamera& cam, const Pose2& pose, double size) {
  const auto corners = sim::markerCornerPixels(cam, pose, size);
  if (!corners) return false;
  const double w = cam.intrinsics().width_px, h = cam.intrinsics().height_px;
  for (const Eigen::Vector2d& p : *corners)
    if (p.x() < kBorderPx || p.y() < kBorderPx || p.x() > w - 1 - kBorderPx ||
        p.y() > h - 1 - kBorderPx)
      return false;
  return true;
}

/// Full mode: frame i from camera i mod cameras, a uniformly random in-view pose and heading.
std::vector<Shot> randomShots(const std::vector<sim::EnvironmentCamera>& cams, int frames,
                              double size, std::mt19937_64& rng) {
  std::vector<Shot> shots;
  std::uniform_real_distribution<double> unit(0.0, 1.0),
      heading(-std::numbers::pi, std::numbers::pi);
  for (int i = 0; i < frames; ++i) {
    const std::size_t c = static_cast<std::size_t>(i) % cams.size();
    const auto& in = cams[c].intrinsics();
    for (;;) {
      const Pose2 pose(cams[c].floorPoint({unit(rng) * in.width_px, unit(rng) * in.height_px}),
                       heading(rng));
      if (!wholeMarkerInView(cams[c], pose, size)) continue;
      shots.push_back({c, pose, true});
      break;
    }
  }
  return shots;
}

/// Tracking mode: passes through the cameras' views in turn, each a gently curving drive at kSpeed
/// from well outside the view across it in a random direction, sampled at kFrameRate; the frames
/// whose marker centre is in the image (the marker may show only partly) until `frames`.
std::vector<Shot> drivenShots(const std::vector<sim::EnvironmentCamera>& cams, int frames,
                              double size, std::mt19937_64& rng) {
  std::vector<Shot> shots;
  std::uniform_real_distribution<double> direction(-std::numbers::pi, std::numbers::pi),
      offset(-1.5, 1.5), turn_rate(-0.06, 0.06);
  const double step = kSpeed / kFrameRate, dt = 1.0 / kFrameRate;
  for (std::size_t pass = 0; static_cast<int>(shots.size()) < frames; ++pass) {
    const std::size_t c = pass % cams.size();
    const auto& cam = cams[c];
    const auto& in = cam.intrinsics();
    const Eigen::Vector2d middle = cam.floorPoint({0.5 * in.width_px, 0.5 * in.height_px});
    const double phi = direction(rng), lateral = offset(rng), rate = turn_rate(rng);
    const Eigen::Vector2d along(std::cos(phi), std::sin(phi)), left(-along.y(), along.x());
    Pose2 pose(middle - 6.0 * along + lateral * left, phi);
    bool entered = false;
    for (int k = 0; k < 600 && static_cast<int>(shots.size()) < frames; ++k) {
      if (cam.inView(pose.translation())) {
        entered = true;
        shots.push_back({c, pose, wholeMarkerInView(cam, pose, size)});
      } else if (entered) {
        break;  // left the view
      }
      pose = Pose2(
          pose.translation() + step * Eigen::Vector2d(std::cos(pose.theta), std::sin(pose.theta)),
          pose.theta + rate * dt);
    }
  }
  return shots;
}

struct ModeResult {
  std::string mode;
  int frames = 0, in_view = 0, detected = 0, false_markers = 0, from_window = 0;
  double centre_sq = 0, corner_sq = 0;
  std::vector<double> ms;

  nlohmann::json toJson() const {
    double mean = 0;
    for (double t : ms) mean += t / static_cast<double>(ms.size());
    nlohmann::json j{
        {"mode", mode},
        {"frames", frames},
        {"frames_in_view", in_view},
        {"detected_fraction", in_view > 0 ? static_cast<double>(detected) / in_view : 0.0},
        {"centre_rms_px", detected > 0 ? std::sqrt(centre_sq / detected) : 0.0},
        {"corner_rms_px", detected > 0 ? std::sqrt(corner_sq / (4.0 * detected)) : 0.0},
        {"ms_per_frame_median", percentile(ms, 0.5)},
        {"ms_per_frame_p95", percentile(ms, 0.95)},
        {"ms_per_frame_mean", mean},
        {"false_markers", false_markers}};
    if (mode == "tracking")
      j["window_fraction"] = frames > 0 ? static_cast<double>(from_window) / frames : 0.0;
    return j;
  }
};

double millisecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

ModeResult runMode(const std::string& mode, const std::vector<sim::EnvironmentCamera>& cams,
                   const std::vector<Shot>& shots, const MarkerDetector& detector,
                   const sim::CameraImageOptions& render, const Options& o) {
  const bool tracking = mode == "tracking";
  std::mt19937_64 noise_rng(o.seed + 1000);
  MarkerTracker tracker(detector, render.marker_id);
  ModeResult r;
  r.mode = mode;
  bool warmed_up = false;
  for (const Shot& shot : shots) {
    const auto& cam = cams[shot.camera];
    const cv::Mat image = sim::renderCameraImage(cam, shot.pose, render, noise_rng);
    if (!warmed_up) {  // first-call allocations stay out of the figures
      (void)detector.detect(image);
      warmed_up = true;
    }
    std::vector<DetectedMarker> markers;
    std::vector<double> times;
    bool from_window = false;
    for (int k = 0; k < o.repeats; ++k) {
      MarkerTracker trial = tracker;  // every repeat starts from the same tracker state
      const auto t0 = std::chrono::steady_clock::now();
      markers = tracking ? trial.detect(image) : detector.detect(image);
      times.push_back(millisecondsSince(t0));
      if (k + 1 == o.repeats) {
        from_window = trial.answeredFromWindow();
        tracker = trial;
      }
    }
    r.ms.push_back(percentile(times, 0.5));
    ++r.frames;
    r.from_window += from_window;
    for (const auto& m : markers) r.false_markers += m.id != render.marker_id;
    if (!shot.in_view) continue;
    ++r.in_view;
    const Eigen::Vector2d centre = *cam.project(shot.pose.translation());
    for (const auto& m : markers) {
      if (m.id != render.marker_id || (m.centre - centre).norm() > kDetectedWithinPx) continue;
      const auto truth = *sim::markerCornerPixels(cam, shot.pose, render.marker_size_m);
      ++r.detected;
      r.centre_sq += (m.centre - centre).squaredNorm();
      for (std::size_t c = 0; c < 4; ++c) r.corner_sq += (m.corners[c] - truth[c]).squaredNorm();
      break;
    }
  }
  return r;
}

}  // namespace marker_detection_bench

void addBenchMarkerDetectionCommand(CLI::App& bench, int& result) {
  namespace mdb = marker_detection_bench;
  auto* cmd = bench.add_subcommand(
      "marker_detection",
      "ArUco marker detection on rendered 640 x 480 ceiling-camera images of the seed-000 camera "
      "floor (1 px blur, noise): detection rate, pixel errors, ms per frame; whole-image search "
      "and tracking along a robot's drive.\n"
      "--json prints one object: {machine, frames, width, height, cameras, repeats, seed, "
      "blur_px, noise_std, marker_size_m, threshold_windows_px [min, max, step], track_margin, "
      "opencv_threads, modes: [{mode (full | tracking), frames, frames_in_view, "
      "detected_fraction, centre_rms_px, corner_rms_px, ms_per_frame_median, ms_per_frame_p95, "
      "ms_per_frame_mean, false_markers, window_fraction (tracking only)}]}");
  auto o = std::make_shared<mdb::Options>();
  cmd->add_option("--frames", o->frames, "frames per mode")->capture_default_str();
  cmd->add_option("--repeats", o->repeats, "detections per frame; a frame's time is their median")
      ->capture_default_str();
  cmd->add_option("--mode", o->mode, "full, tracking or both")->capture_default_str();
  cmd->add_option("--seed", o->seed, "random seed of poses, drives and noise")
      ->capture_default_str();
  cmd->add_option("--window-min", o->detector.threshold_window_min_px,
                  "smallest adaptive threshold window [px] (OpenCV's default: 3)")
      ->capture_default_str();
  cmd->add_option("--window-max", o->detector.threshold_window_max_px,
                  "largest adaptive threshold window [px] (OpenCV's default: 23)")
      ->capture_default_str();
  cmd->add_option("--window-step", o->detector.threshold_window_step_px,
                  "step between threshold windows [px]")
      ->capture_default_str();
  cmd->add_option("--margin", o->detector.track_margin,
                  "tracking window around the last detection [marker sides]")
      ->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    if (o->frames < 1) throw ConfigError("--frames must be >= 1");
    if (o->repeats < 1) throw ConfigError("--repeats must be >= 1");
    if (o->mode != "full" && o->mode != "tracking" && o->mode != "both")
      throw ConfigError("--mode must be full, tracking or both, got '" + o->mode + "'");
    std::optional<camera_network::MarkerDetector> detector;
    try {
      detector.emplace(o->detector);
    } catch (const std::invalid_argument& e) {
      throw ConfigError(std::string("bench marker_detection: ") + e.what());
    }
    const sim::World world = sim::World::builtinCameraFloor();
    const sim::CameraIntrinsics intrinsics;
    std::vector<sim::EnvironmentCamera> cams;
    for (const auto& site : world.cameraSites()) cams.emplace_back(site, intrinsics);
    const sim::CameraImageOptions render;

    std::vector<mdb::ModeResult> modes;
    for (const std::string mode : {"full", "tracking"}) {
      if (o->mode != "both" && o->mode != mode) continue;
      std::mt19937_64 rng(o->seed);
      const auto shots = mode == "full"
                             ? mdb::randomShots(cams, o->frames, render.marker_size_m, rng)
                             : mdb::drivenShots(cams, o->frames, render.marker_size_m, rng);
      if (!o->json)
        std::cerr << "[bench marker_detection] " << mode << ": " << shots.size() << " frames\n";
      modes.push_back(mdb::runMode(mode, cams, shots, *detector, render, *o));
    }

    if (o->json) {
      nlohmann::json list = nlohmann::json::array();
      for (const auto& m : modes) list.push_back(m.toJson());
      std::cout << nlohmann::json{{"machine", machineDescription()},
                                  {"frames", o->frames},
                                  {"width", intrinsics.width_px},
                                  {"height", intrinsics.height_px},
                                  {"cameras", cams.size()},
                                  {"repeats", o->repeats},
                                  {"seed", o->seed},
                                  {"blur_px", render.blur_px},
                                  {"noise_std", render.noise_std},
                                  {"marker_size_m", render.marker_size_m},
                                  {"threshold_windows_px",
                                   {o->detector.threshold_window_min_px,
                                    o->detector.threshold_window_max_px,
                                    o->detector.threshold_window_step_px}},
                                  {"track_margin", o->detector.track_margin},
                                  {"opencv_threads", cv::getNumThreads()},
                                  {"modes", list}}
                       .dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << o->frames << " frames per mode, " << intrinsics.width_px << " x "
              << intrinsics.height_px << ", " << cams.size()
              << " cameras of the seed-000 camera floor (focal " << intrinsics.focal_px << " px, "
              << intrinsics.ceiling_height << " m), marker " << render.marker_size_m << " m id "
              << render.marker_id << ", blur " << render.blur_px << " px, noise "
              << render.noise_std << " grey levels\n"
              << "threshold windows " << o->detector.threshold_window_min_px << ".."
              << o->detector.threshold_window_max_px << " px step "
              << o->detector.threshold_window_step_px << ", tracking margin "
              << o->detector.track_margin << " marker sides; " << o->repeats
              << " detections per frame (median); OpenCV threads " << cv::getNumThreads() << "\n\n"
              << std::left << std::setw(10) << "mode" << std::right << std::setw(8) << "frames"
              << std::setw(9) << "in view" << std::setw(10) << "detected" << std::setw(12)
              << "centre px" << std::setw(11) << "corner px" << std::setw(11) << "ms median"
              << std::setw(9) << "ms p95" << std::setw(9) << "ms mean" << std::setw(8) << "false"
              << std::setw(8) << "window"
              << "\n";
    for (const auto& m : modes) {
      const nlohmann::json j = m.toJson();
      std::cout << std::left << std::setw(10) << m.mode << std::right << std::setw(8) << m.frames
                << std::setw(9) << m.in_view << std::fixed << std::setprecision(3) << std::setw(10)
                << j["detected_fraction"].get<double>() << std::setw(12)
                << j["centre_rms_px"].get<double>() << std::setw(11)
                << j["corner_rms_px"].get<double>() << std::setw(11)
                << j["ms_per_frame_median"].get<double>() << std::setw(9)
                << j["ms_per_frame_p95"].get<double>() << std::setw(9)
                << j["ms_per_frame_mean"].get<double>() << std::setw(8) << m.false_markers;
      if (j.contains("window_fraction"))
        std::cout << std::setw(8) << j["window_fraction"].get<double>();
      std::cout << "\n";
    }
    result = 0;
  });
}

}  // namespace tessera::app
