// rgbd_mapper actor: the 3D maps of an RGB-D SLAM run (docs/algorithms.md#rgb-d-maps) from the
// front end's keyframes and the keyframe graph's poses.
//
// Subscribes:
//   keyframes        msg::Keyframe       reliable: each keyframe's downsampled depth becomes a
//                                        voxel-filtered cloud (makeKeyframeCloud) in its camera
//                                        frame, kept per keyframe, added to the CloudMap and
//                                        inserted into the OctoMap at the keyframe's latest pose
//   keyframe_poses   msg::KeyframePoses  reliable: optimised poses; when one moves a keyframe by
//                                        more than move_threshold_m / move_threshold_rad, every
//                                        pose of the message is applied (the clouds move) and the
//                                        OctoMap is rebuilt in the background; a mapped
//                                        keyframe missing from it (id below its newest) left the
//                                        graph (lifelong mode): its cloud is dropped and the
//                                        OctoMap rebuilt without it
//                                        (OctoMapBuilder::rebuild: the mailbox is not blocked;
//                                        the old tree is served until the new one swaps in; a
//                                        request made meanwhile follows it)
// Publishes:
//   map_cloud        msg::PointCloud     a preview of the 3D map for viewers: the centres of the
//                                        OctoMap's occupied voxels (OctoMapBuilder::
//                                        occupiedVoxels; at most preview_max_points, at a coarser
//                                        voxel when the leaves are more, voxelSize = the edge
//                                        used), no colour, frameId = the keyframes' world frame.
//                                        Every preview_period_s of run clock when the OctoMap
//                                        changed since the last one (0 = never), and at stop
//                                        when it changed since then.
// Writes (with an output directory, in stop(), once the OctoMap holds the latest poses): cloud.pcd
// and cloud.ply (the assembled cloud, pcl_viewer / CloudCompare) and map.bt (octovis); also every
// save_period_s when that is > 0.
// Threads: clouds are built and stored, and inserted into the OctoMap, on a thread the actor owns
// (the handler waits for it; see the .cpp for why); the OctoMap rebuild runs on its own thread.
// Colour: keyframe messages carry no colour image, so the clouds have none (x y z only); viewers
// colour by height themselves (apps/profiles/rgbd_slam.yaml names the tools).
// A bad keyframe (no or mismatched depth, non-finite pose, bad intrinsics) and a bad pose entry
// (non-finite, or an id the map has not seen) are counted by kind and skipped, never a crash.
#pragma once

#include <tessera/msg/cloud.capnp.h>
#include <tessera/msg/keyframe.capnp.h>
#include <tessera/mapping3d/cloud_map.hpp>
#include <tessera/mapping3d/keyframe_cloud.hpp>
#include <tessera/mapping3d/octomap_builder.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <string>

namespace tessera::mapping3d {

struct RgbdMapperOptions {
  /// Keyframe messages already keep every 4th depth pixel (rgbd_front_end keyframe_depth_step),
  /// so the cloud takes every sample of that block: stride 1.
  KeyframeCloudOptions cloud = [] {
    KeyframeCloudOptions o;
    o.stride = 1;
    return o;
  }();
  CloudMapOptions map;
  OctoMapOptions octomap;
  double move_threshold_m = 0.01;     ///< [m] a keyframe moved farther than this is re-placed
  double move_threshold_rad = 0.005;  ///< [rad] likewise for its rotation
  std::string pcd_file = "cloud.pcd";
  std::string ply_file = "cloud.ply";
  std::string octomap_file = "map.bt";
  double save_period_s = 0;  ///< [s] also write the outputs this often (run clock); 0 = at stop
  double preview_period_s = 1.0;    ///< [s] map_cloud at most this often (run clock); 0 = off
  int preview_max_points = 100000;  ///< map_cloud points at most (coarser voxels beyond)

  template <class V>
  void visit(V& v) {
    v("cloud", cloud, "one keyframe's cloud from its depth (stride, depth range, voxel leaf)");
    v("map", map, "the assembled global cloud (voxel leaf)");
    v("octomap", octomap, "the OctoMap (resolution, max range, log-odds clamping, insertion)");
    v("move_threshold_m", move_threshold_m,
      "re-place keyframes and rebuild the OctoMap when a pose moves more than this [m]");
    v("move_threshold_rad", move_threshold_rad,
      "re-place keyframes and rebuild the OctoMap when a pose turns more than this [rad]");
    v("pcd_file", pcd_file, "assembled cloud (binary PCD) in the output directory; empty: none");
    v("ply_file", ply_file, "assembled cloud (binary PLY) in the output directory; empty: none");
    v("octomap_file", octomap_file, "OctoMap (.bt) in the output directory; empty: none");
    v("save_period_s", save_period_s, "also write the outputs this often; 0 = only at stop [s]");
    v("preview_period_s", preview_period_s,
      "publish map_cloud (the OctoMap's occupied voxel centres) this often when the map changed; "
      "0 = never [s]");
    v("preview_max_points", preview_max_points,
      "map_cloud holds at most this many points: beyond, coarser voxels (2x, 4x, ... the "
      "resolution)");
  }
};

class RgbdMapperActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options (naming the key).
  explicit RgbdMapperActor(RgbdMapperOptions options);
  ~RgbdMapperActor() override;
  void configure(ActorContext& ctx) override;
  void stop() override;
  /// keyframes (received, mapped, bad by kind), points, OctoMap leaves and memory, pose messages,
  /// keyframes moved, rebuilds, ms per keyframe (cloud, OctoMap insertion), the files written.
  void summarize(Summary& out) const override;

  const CloudMap& cloudMap() const { return cloud_map_; }
  const OctoMapBuilder& octomap() const { return *octomap_; }

 private:
  void onKeyframe(const Message<msg::Keyframe>& m);
  void onPoses(const Message<msg::KeyframePoses>& m);
  void bad(std::map<std::string, std::uint64_t>& counts, const std::string& what,
           const std::string& why);
  void writeOutputs();
  /// Publishes map_cloud when the OctoMap changed since the last preview.
  void publishPreview();

  RgbdMapperOptions options_;
  CloudMap cloud_map_;
  std::unique_ptr<OctoMapBuilder> octomap_;
  class MapThread;  ///< where clouds are built and stored (see the .cpp)
  std::unique_ptr<MapThread> map_thread_;
  std::string output_dir_;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::PointCloud> cloud_pub_;
  std::string world_frame_ = "world";     ///< the keyframes' frame (their header's frameId)
  std::uint64_t previewed_revision_ = 0;  ///< OctoMap revision of the last map_cloud
  std::uint64_t previews_ = 0;
  std::size_t preview_points_ = 0;
  double preview_voxel_m_ = 0, preview_ms_total_ = 0, preview_ms_max_ = 0;

  std::uint64_t keyframes_ = 0, mapped_ = 0, empty_clouds_ = 0, keyframes_dropped_ = 0;
  std::uint64_t pose_messages_ = 0, keyframes_moved_ = 0, rebuilds_ = 0, saves_ = 0;
  std::map<std::string, std::uint64_t> keyframes_bad_, poses_bad_;
  double cloud_ms_total_ = 0, insert_ms_total_ = 0, insert_ms_max_ = 0, write_ms_ = 0;
  double assemble_ms_ = 0, stop_wait_ms_ = 0;
  std::size_t assembled_points_ = 0;
  std::string pcd_path_, ply_path_, octomap_path_, write_error_;
};

}  // namespace tessera::mapping3d
