// WorldWriterActor ("world_writer"): writes the ground truth of a simulated world into the run's
// output folder at start, so SLAM results can be scored against it. Publishes nothing.
//
//   walls_file      true wall faces, wallSegments(): "x0 y0 x1 y1" per line [m], free space on
//                   the left of (x0,y0)->(x1,y1); '#' comments (the first gives the count)
//   landmarks_file  the world's point landmarks: "id x y" per line ('#' comments)
//   image_file      the wall bitmap as an image (e.g. .pgm/.png, top row = highest y)
// Each is skipped when empty; nothing is written when the run writes no files.
#pragma once

#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/sim/world.hpp>

#include <string>

namespace tessera::sim {

struct WorldWriterOptions {
  std::string world = "builtin:room";
  double world_resolution = 0.05;
  std::string walls_file = "walls.txt";
  double walls_min_length = 0.3;
  std::string landmarks_file;
  std::string image_file;

  template <class V>
  void visit(V& v) {
    v("world", world, "'builtin:NAME' or the path of a PGM/PNG map, as for the simulator");
    v("world_resolution", world_resolution, "metres per pixel of an image world");
    v("walls_file", walls_file, "true wall faces, 'x0 y0 x1 y1' per line; empty = none");
    v("walls_min_length", walls_min_length, "wall faces shorter than this [m] are not listed");
    v("landmarks_file", landmarks_file, "true landmarks, 'id x y' per line; empty = none");
    v("image_file", image_file, "the wall bitmap as an image (.pgm/.png); empty = none");
  }
};

class WorldWriterActor final : public Actor {
 public:
  /// Loads the world; throws ConfigError naming the option.
  explicit WorldWriterActor(WorldWriterOptions options);
  void configure(ActorContext& ctx) override { ctx_ = &ctx; }
  /// Writes the files; throws std::runtime_error naming a file it cannot write.
  void start() override;
  /// wall_segments, landmarks (counts written).
  void summarize(Summary& out) const override;

 private:
  WorldWriterOptions options_;
  World world_;
  ActorContext* ctx_ = nullptr;
  std::int64_t walls_written_ = 0, landmarks_written_ = 0;
};

}  // namespace tessera::sim
