// Actors that turn topics into the files a user looks at, inside the run's output folder
// (ctx.outputDir(); both do nothing when the run writes no files).
//
// map_writer          subscribes "map" (msg::OccupancyGrid, keep_latest(1)) and in stop() writes
//                     the last map as <out>/<basename>.pgm/.yaml/.png (ROS map_server format).
// trajectory_writer   subscribes "poses" (reliable; type chosen by `message`) and streams one
//                     TUM line per pose to <out>/<file> as they arrive; flushed at stop().
#pragma once

#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>

#include <cstdint>
#include <memory>
#include <string>

namespace tessera::mapping {

struct MapWriterOptions {
  std::string basename = "map";
  double occupied_thresh = 0.65;
  double free_thresh = 0.196;
  bool png = true;

  template <class V>
  void visit(V& v) {
    v("basename", basename, "file name without extension, relative to the output folder");
    v("occupied_thresh", occupied_thresh, "cells with probability above are drawn occupied");
    v("free_thresh", free_thresh, "cells with probability below are drawn free");
    v("png", png, "also write <basename>.png");
  }
};

class MapWriterActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit MapWriterActor(MapWriterOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  void summarize(Summary& out) const override;

 private:
  MapWriterOptions options_;
  ActorContext* ctx_ = nullptr;
  Message<msg::OccupancyGrid> latest_;
  std::uint64_t maps_received_ = 0;
  std::string map_path_, error_;
};

struct TrajectoryWriterOptions {
  std::string file = "trajectory.tum";
  std::string message = "ground_truth";

  template <class V>
  void visit(V& v) {
    v("file", file, "TUM file to write, relative to the output folder");
    v("message", message,
      "message type on 'poses': ground_truth | odometry | pose_stamped (planar) | "
      "ground_truth_3d (GroundTruthPose3D) | pose_3d (PoseStamped3D, an estimate) (both "
      "written in full 3D)");
  }
};

class TrajectoryWriterActor final : public Actor {
 public:
  /// Throws ConfigError on an unknown `message` or an empty `file`.
  explicit TrajectoryWriterActor(TrajectoryWriterOptions options);
  ~TrajectoryWriterActor() override;
  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  void summarize(Summary& out) const override;

 private:
  void write3d(const tessera::mapping::TumPose& pose);

  TrajectoryWriterOptions options_;
  ActorContext* ctx_ = nullptr;
  std::unique_ptr<tessera::mapping::TumWriter> writer_;
  std::string path_, error_;
  std::uint64_t poses_written_ = 0;
};

}  // namespace tessera::mapping
