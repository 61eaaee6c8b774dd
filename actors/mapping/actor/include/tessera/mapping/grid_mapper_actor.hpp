// grid_mapper actor: occupancy grid mapping with known poses (e.g. simulator ground truth).
//
// Subscribes (local names; remap in the profile):
//   scan  msg::LaserScan      keep_latest(scan_queue)   laser sweeps, with the laser's mounting
//   pose  pose_message type   keep_latest(pose_queue)   base_link pose in the map frame
// Publishes:
//   map   msg::OccupancyGrid  every publish_period_s of runtime time when the map changed, and
//                             once more in stop() (the final map; cropped to the known cells)
//
// Each scan is paired with the pose of equal stamp, or interpolated between the two poses that
// bracket its stamp (at most max_pose_gap_s apart). A scan newer than every pose waits in a
// small buffer until its pose arrives; scans that cannot be paired are dropped and counted.
// With hold_scans, a scan (one per hold_period_s) instead waits as long as it takes, packed
// (PackedRangeScan, 16 bits a beam), and the poses come on a reliable mailbox: for poses that
// arrive at the end, such as a SLAM's final trajectory published at stop, which gives the map
// drawn from every scan at its smoothed pose (docs/algorithms.md#final-map-from-the-scans).
// The laser's pose is robot pose ⊕ the scan's mount fields. The core's options
// (GridMapperCoreOptions) are the group `grid`.
#pragma once

#include <tessera/geometry/pose_history.hpp>
#include <tessera/mapping/grid_mapper.hpp>
#include <tessera/mapping/packed_range_scan.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

namespace tessera::mapping {

struct GridMapperOptions {
  GridMapperCoreOptions grid;
  double publish_period_s = 1.0;
  std::string frame_id = "map";
  std::string pose_message = "ground_truth";
  int scan_queue = 8;
  int pose_queue = 32;
  int scan_buffer = 16;
  int pose_history = 512;
  double max_pose_gap_s = 0.5;
  bool hold_scans = false;
  double hold_period_s = 0.0;

  template <class V>
  void visit(V& v) {
    v("grid", grid, "the grid: resolution, log-odds, beam insertion, growth");
    v("publish_period_s", publish_period_s,
      "publish the map this often [s of runtime time] when it changed; 0: only at stop");
    v("frame_id", frame_id, "frame of the published map (the pose stream's frame)");
    v("pose_message", pose_message,
      "message type on 'pose': ground_truth | odometry | pose_stamped");
    v("scan_queue", scan_queue, "scan mailbox size (keep-latest: older scans are dropped)");
    v("pose_queue", pose_queue, "pose mailbox size (keep-latest)");
    v("scan_buffer", scan_buffer, "scans kept waiting for a pose with a later stamp");
    v("pose_history", pose_history, "poses remembered for pairing with late scans");
    v("max_pose_gap_s", max_pose_gap_s,
      "do not interpolate between poses further apart than this [s]; drop the scan");
    v("hold_scans", hold_scans,
      "keep scans (packed, 2 bytes a beam) however long their poses take, and read the poses "
      "reliably: for a trajectory published at the end of the run (scan_buffer then unused)");
    v("hold_period_s", hold_period_s,
      "with hold_scans, keep a scan only when this long [s, scan stamps] has passed since the "
      "last one kept (0: every scan): less memory and insertion time");
  }
  // The core's keys moved into the group `grid`.
  static constexpr RenamedKey kRenamedKeys[] = {
      {"resolution", "grid.resolution"},
      {"l_occ", "grid.l_occ"},
      {"l_free", "grid.l_free"},
      {"l_min", "grid.l_min"},
      {"l_max", "grid.l_max"},
      {"max_range", "grid.max_range"},
      {"max_free_range", "grid.max_free_range"},
      {"max_side_cells", "grid.max_side_cells"},
  };
};

class GridMapperActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options.
  explicit GridMapperActor(GridMapperOptions options);

  void configure(ActorContext& ctx) override;
  void stop() override;
  void summarize(Summary& out) const override;

  const GridMapper& mapper() const { return mapper_; }

 private:
  void onScan(const Message<msg::LaserScan>& scan);
  /// With hold_scans: inserts the scan if its pose is known, else packs it into held_.
  void holdScan(const Message<msg::LaserScan>& scan);
  void onPose(Nanos stamp, const tessera::Pose2& pose);
  /// Inserts the scan if its pose is known; returns false when it must keep waiting.
  bool tryInsert(const Message<msg::LaserScan>& scan);
  bool tryInsert(std::int64_t stamp, const tessera::grid::RangeScan& ranges,
                 const tessera::Pose2& mount);
  void publishMap();

  GridMapperOptions options_;
  GridMapper mapper_;
  Publisher<msg::OccupancyGrid> map_pub_;
  tessera::PoseHistory poses_;
  std::deque<Message<msg::LaserScan>> waiting_;  // scans newer than every pose, oldest first
  std::deque<PackedRangeScan> held_;             // with hold_scans: the same, packed, unbounded
  std::vector<float> unpacked_;                  // ranges of the held scan being inserted
  std::optional<Nanos> last_held_;               // stamp of the last scan kept (inserted or held)
  std::uint64_t scans_not_held_ = 0, scans_unusable_ = 0;
  std::size_t held_bytes_ = 0, held_bytes_peak_ = 0, held_peak_ = 0;
  Nanos last_scan_stamp_ = 0;
  bool dirty_ = false;  // inserted since the last publish
  std::uint64_t scans_exact_ = 0, scans_interpolated_ = 0;
  std::uint64_t scans_dropped_no_pose_ = 0, scans_dropped_buffer_full_ = 0;
  std::uint64_t maps_published_ = 0, poses_invalid_ = 0;  // poses_invalid_: NaN/inf poses ignored
};

}  // namespace tessera::mapping
