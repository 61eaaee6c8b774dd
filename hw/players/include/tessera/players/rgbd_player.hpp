// RgbdPlayerActor ("rgbd_player"): replays an RGB-D dataset folder (TUM RGB-D or Microsoft
// 7-Scenes, see tessera/datasets/rgbd_sequence.hpp) as messages. A finite source: it calls
// finished() after the last frame.
//
// Publishes (local topic names):
//   rgbd             msg::RgbdFrame          colour "rgb8" + depth ("16UC1" raw or "32FC1" metres),
//                                            intrinsics, depth scale, ground truth when known
//   ground_truth     msg::GroundTruthPose3D  frame world_frame, child frame_id (camera-to-world);
//                                            only for frames the dataset has a pose for
//   ground_truth_2d  msg::GroundTruthPose    the same, projected to the world x-y plane: (x, y,
//                                            heading of the optical axis). For 2D tools such as
//                                            trajectory_writer; only meaningful when world z is up
//                                            (TUM's mocap frame), not for 7-Scenes.
//
// Timing: frame i is published at start + (t_i - t_first) / rate on the runtime clock, through a
// chain of ctx.callAt timers; the header stamp is that time, so stamps keep the dataset's spacing
// at rate 1 (datasetTimeS keeps the original time). 7-Scenes has no timestamps: frames are
// index / fps apart (30 Hz). Images are decoded in the timer callback (see summary load_ms_*).
// A missing or corrupt image stops the run (requestStop) with the file name and frame number.
// Option and dataset-index errors throw ConfigError from the constructor.
#pragma once

#include <tessera/msg/image.capnp.h>
#include <tessera/datasets/rgbd_sequence.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <string>

namespace tessera::players {

struct RgbdPlayerOptions {
  std::string path;
  std::string layout = "auto";
  double rate = 1.0;
  std::int64_t first_frame = 0;
  std::int64_t last_frame = -1;
  std::string depth = "uint16";
  double fps = 30;
  double max_time_difference = 0.02;
  bool use_associations_file = false;
  std::string camera = "auto";
  std::string frame_id = "camera";
  std::string world_frame = "world";

  template <class V>
  void visit(V& v) {
    v("path", path, "dataset folder (required), e.g. --set player.path=DIR");
    v("layout", layout, "auto | tum | 7scenes (auto: from the folder's files)");
    v("rate", rate,
      "playback speed factor (> 0): stamps and timers advance (t - t_first) / rate; to pace a "
      "replay without changing stamps use the profile's sim_rate instead");
    v("first_frame", first_frame, "first frame to play (0-based index into the sequence)");
    v("last_frame", last_frame, "last frame to play, inclusive; -1 = to the end");
    v("depth", depth, "uint16 (raw, 16UC1, depthScale units per metre) | float (32FC1 metres)");
    v("fps", fps, "7-Scenes only: frame rate that defines timestamps [Hz] (no timestamps given)");
    v("max_time_difference", max_time_difference,
      "TUM only: largest |t_rgb - t_depth| to pair colour with depth [s]");
    v("use_associations_file", use_associations_file,
      "TUM only: take pairs from associations.txt instead of pairing rgb.txt with depth.txt");
    v("camera", camera,
      "TUM only: intrinsics auto | freiburg1 | freiburg2 | freiburg3 | ros_default");
    v("frame_id", frame_id, "camera optical frame name in the headers");
    v("world_frame", world_frame, "frame of the ground-truth poses");
  }
};

class RgbdPlayerActor final : public Actor {
 public:
  /// Reads the dataset index (text files; no images yet). Throws ConfigError naming the option or
  /// the dataset file.
  explicit RgbdPlayerActor(RgbdPlayerOptions options);
  void configure(ActorContext& ctx) override;
  /// frames_in_dataset, frames_published, ground_truth_published, layout, load_ms_mean,
  /// load_ms_max, dataset_duration_s, error (when a frame failed).
  void summarize(Summary& out) const override;

  const datasets::RgbdSequence& sequence() const { return sequence_; }
  /// The frames it plays, [begin, end) of sequence().frames (first_frame / last_frame applied).
  std::size_t beginFrame() const { return begin_; }
  std::size_t endFrame() const { return end_; }

 private:
  void playNext();
  Nanos timeOf(std::size_t frame) const;

  RgbdPlayerOptions options_;
  datasets::RgbdSequence sequence_;
  bool float_depth_ = false;
  std::size_t begin_ = 0, end_ = 0, next_ = 0;  // frames [begin_, end_) are played
  Nanos start_ = 0;

  ActorContext* ctx_ = nullptr;
  Publisher<msg::RgbdFrame> rgbd_pub_;
  Publisher<msg::GroundTruthPose3D> gt_pub_;
  Publisher<msg::GroundTruthPose> gt2d_pub_;

  std::int64_t frames_published_ = 0, gt_published_ = 0;
  double load_ms_total_ = 0, load_ms_max_ = 0;
  std::string error_;
};

}  // namespace tessera::players
