// WorldWriterActor ("world_writer"): writes the ground truth of a simulated world into the run's
// output folder at start, so SLAM results can be scored against it, and with publish_map
// publishes the true maps, so localisation, navigation and goal generation can run on them in a
// self-contained simulated profile.
//
//   walls_file      true wall faces, wallSegments(): "x0 y0 x1 y1" per line [m], free space on
//                   the left of (x0,y0)->(x1,y1); '#' comments (the first gives the count)
//   landmarks_file  the world's point landmarks: "id x y" per line ('#' comments)
//   image_file      the wall bitmap as an image (e.g. .pgm/.png, top row = highest y)
// Each is skipped when empty; nothing is written when the run writes no files.
//
// Publishes (only with publish_map; nothing is advertised without it), at t = 0 and then every
// map_period_s, both with frame "map", stamp = now, the world's resolution and size in cells
// and origin (0, 0, 0) (cell (0, 0)'s outer corner at the world's origin):
//   map           msg::OccupancyGrid  the wall bitmap: 100 wall, 0 free (what the planar laser
//                                     sees)
//   obstacle_map  msg::OccupancyGrid  footprintOccupancy(world, robot_height) (collision.hpp):
//                                     walls plus the furniture below the robot's top, 100, else 0
#pragma once

#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/sim/world.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace tessera::sim {

struct WorldWriterOptions {
  std::string world = "builtin:room";
  double world_resolution = 0.05;
  std::string walls_file = "walls.txt";
  double walls_min_length = 0.3;
  std::string landmarks_file;
  std::string image_file;
  bool publish_map = false;
  double robot_height = 1.0;
  double map_period_s = 2.0;

  template <class V>
  void visit(V& v) {
    v("world", world, "'builtin:NAME' or the path of a PGM/PNG map, as for the simulator");
    v("world_resolution", world_resolution, "metres per pixel of an image world");
    v("walls_file", walls_file, "true wall faces, 'x0 y0 x1 y1' per line; empty = none");
    v("walls_min_length", walls_min_length, "wall faces shorter than this [m] are not listed");
    v("landmarks_file", landmarks_file, "true landmarks, 'id x y' per line; empty = none");
    v("image_file", image_file, "the wall bitmap as an image (.pgm/.png); empty = none");
    v("publish_map", publish_map,
      "publish the true wall map on 'map' and the obstacle map on 'obstacle_map'");
    v("robot_height", robot_height,
      "obstacle_map: furniture whose bottom is below this height [m] is an obstacle");
    v("map_period_s", map_period_s, "publish_map: seconds between publications (first at 0)");
  }
};

class WorldWriterActor final : public Actor {
 public:
  /// Loads the world; throws ConfigError naming the option.
  explicit WorldWriterActor(WorldWriterOptions options);
  void configure(ActorContext& ctx) override;
  /// Writes the files; throws std::runtime_error naming a file it cannot write.
  void start() override;
  /// wall_segments, landmarks (counts written), maps_published (publications of the pair).
  void summarize(Summary& out) const override;

 private:
  WorldWriterOptions options_;
  World world_;
  void publishMaps();
  void publishGrid(const Publisher<msg::OccupancyGrid>& pub, const std::vector<std::int8_t>& cells);

  ActorContext* ctx_ = nullptr;
  Publisher<msg::OccupancyGrid> map_pub_, obstacle_pub_;
  std::vector<std::int8_t> wall_cells_, obstacle_cells_;  // computed once (the world is fixed)
  std::int64_t walls_written_ = 0, landmarks_written_ = 0, maps_published_ = 0;
};

}  // namespace tessera::sim
