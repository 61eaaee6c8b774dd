// Writers for the simulated sensor data of the camera-network and landmark scenarios, into the
// run's output folder (nothing when the run writes no files). Stamps are written as seconds with
// 9 decimals (exact nanoseconds); CSV files start with one header line.
//
// camera_log_writer    subscribes "detections" (msg::MarkerDetection) and "events"
//                      (msg::CameraEvent), reliable; streams
//                        <detections_file>: stamp_s,camera_id,detected,u,v,pixel_std
//                        <events_file>:     stamp_s,camera_id,entered
// landmark_log_writer  subscribes "landmarks" (msg::LandmarkScan) and "control"
//                      (msg::DriveControl), reliable; streams
//                        <observations_file>: stamp_s,id,range,bearing,range_std,bearing_std
//                                             (one line per observation)
//                        <controls_file>:     stamp_s,speed,steering,wheelbase,dt_s
// landmark_map_writer  subscribes "landmark_map" (msg::LandmarkMap, keep_latest(1)) and in
//                      stop() writes the last map as `id x y` lines with '#' comments (the format
//                      `tessera eval landmarks` reads).
// line_map_writer      subscribes "line_map" (msg::LineMap, keep_latest(1)) and, with
//                      draw_trajectory, "poses" (msg::PoseStamped, reliable); in stop() writes
//                      the last map as <lines_file> (CSV, common/line_map_io.hpp) and
//                      <svg_file> (drawing over the true walls of <walls_file> when that file
//                      exists in the output folder, e.g. written by world_writer), and scores
//                      the map against those walls in its summary.
#pragma once

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/landmark.capnp.h>
#include <tessera/msg/lines.capnp.h>
#include <tessera/io/atomic_file.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace tessera::mapping {

struct CameraLogWriterOptions {
  std::string detections_file = "camera_detections.csv";
  std::string events_file = "camera_events.csv";

  template <class V>
  void visit(V& v) {
    v("detections_file", detections_file, "CSV of marker detections, in the output folder");
    v("events_file", events_file, "CSV of enter/leave events, in the output folder");
  }
};

class CameraLogWriterActor final : public Actor {
 public:
  /// Throws ConfigError for empty file names.
  explicit CameraLogWriterActor(CameraLogWriterOptions options);
  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  void summarize(Summary& out) const override;

 private:
  CameraLogWriterOptions options_;
  ActorContext* ctx_ = nullptr;
  std::unique_ptr<tessera::io::AtomicFile> detections_, events_;  ///< renamed into place at stop()
  std::int64_t detections_written_ = 0, events_written_ = 0;
  std::string error_;
};

struct LandmarkLogWriterOptions {
  std::string observations_file = "landmark_observations.csv";
  std::string controls_file = "controls.csv";

  template <class V>
  void visit(V& v) {
    v("observations_file", observations_file, "CSV of range-bearing observations");
    v("controls_file", controls_file, "CSV of drive controls");
  }
};

class LandmarkLogWriterActor final : public Actor {
 public:
  /// Throws ConfigError for empty file names.
  explicit LandmarkLogWriterActor(LandmarkLogWriterOptions options);
  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  void summarize(Summary& out) const override;

 private:
  LandmarkLogWriterOptions options_;
  ActorContext* ctx_ = nullptr;
  std::unique_ptr<tessera::io::AtomicFile> observations_, controls_;  ///< renamed at stop()
  std::int64_t observations_written_ = 0, controls_written_ = 0;
  std::string error_;
};

struct LandmarkMapWriterOptions {
  std::string file = "landmarks.txt";

  template <class V>
  void visit(V& v) {
    v("file", file, "text file of `id x y` lines, in the output folder");
  }
};

class LandmarkMapWriterActor final : public Actor {
 public:
  /// Throws ConfigError for an empty file name.
  explicit LandmarkMapWriterActor(LandmarkMapWriterOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  void summarize(Summary& out) const override;

 private:
  LandmarkMapWriterOptions options_;
  ActorContext* ctx_ = nullptr;
  Message<msg::LandmarkMap> latest_;
  std::int64_t landmarks_written_ = 0;
  std::string path_, error_;
};

struct LineMapWriterOptions {
  std::string lines_file = "lines.csv";
  std::string svg_file = "lines.svg";
  std::string walls_file;
  bool draw_trajectory = true;
  double pixels_per_m = 60.0;

  template <class V>
  void visit(V& v) {
    v("lines_file", lines_file, "CSV of the map lines, in the output folder; empty = none");
    v("svg_file", svg_file, "SVG drawing of the map lines; empty = none");
    v("walls_file", walls_file,
      "true walls ('x0 y0 x1 y1' lines) in the output folder, drawn beneath the map and used to "
      "score it; empty or absent = none");
    v("draw_trajectory", draw_trajectory, "subscribe to poses and draw the trajectory");
    v("pixels_per_m", pixels_per_m, "SVG scale [px/m] (> 0)");
  }
};

class LineMapWriterActor final : public Actor {
 public:
  /// Throws ConfigError for bad options.
  explicit LineMapWriterActor(LineMapWriterOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  /// lines_written, and with walls: walls, walls_matched, lines_on_walls.
  void summarize(Summary& out) const override;

 private:
  LineMapWriterOptions options_;
  ActorContext* ctx_ = nullptr;
  Message<msg::LineMap> latest_;
  std::vector<Eigen::Vector2d> trajectory_;
  std::int64_t lines_written_ = 0;
  int walls_ = -1, walls_matched_ = 0, lines_on_walls_ = 0;
  std::string error_;
};

}  // namespace tessera::mapping
