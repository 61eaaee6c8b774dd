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
#pragma once

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/landmark.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>

#include <cstdint>
#include <fstream>
#include <string>

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
  std::ofstream detections_, events_;
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
  std::ofstream observations_, controls_;
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

}  // namespace tessera::mapping
