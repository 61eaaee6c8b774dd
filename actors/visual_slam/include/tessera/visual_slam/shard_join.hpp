// ShardJoin: places the pieces of a sequence that was tracked in shards in one world frame — the
// stitching step of batch reprocessing (docs/algorithms.md#batch-reprocessing).
//
// A shard is a run of consecutive frames tracked on its own, from its first frame, so its poses
// (camera-to-shard, metres) and stamps (ns) are in its own frame and clock. Shard k starts a few
// frames before shard k−1 ends. It is placed by the first frame both tracked, f ≥ its first frame:
//   world←k = world←(k−1) · P_{k−1}(f) · P_k(f)⁻¹,   offset_k = offset_{k−1} + t_{k−1}(f) − t_k(f)
// Shard 0 defines the world frame and clock. From shard k's first frame on, its frames are the
// ones kept; shard k−1's copies of them are dropped.
#pragma once

#include <tessera/geometry/pose3.hpp>

#include <cstdint>
#include <vector>

namespace tessera::visual_slam {

struct ShardFramePose {
  std::uint32_t frame = 0;    ///< index of the frame in the whole sequence
  std::int64_t stamp_ns = 0;  ///< in the shard's clock
  Pose3 pose;                 ///< camera-to-shard
};

struct ShardTrack {
  std::uint32_t first_frame = 0;      ///< first frame the shard was given
  std::vector<ShardFramePose> poses;  ///< the frames it tracked, any order
};

struct ShardPlacement {
  Pose3 world_from_shard;            ///< identity for shard 0
  std::int64_t stamp_offset_ns = 0;  ///< global stamp = shard stamp + this
  std::uint32_t join_frame = 0;      ///< the frame shared with the previous shard (0 for shard 0)
  std::uint32_t first_frame = 0;     ///< frames kept: [first_frame, next shard's first_frame)
};

/// One placement per shard, in order. Throws std::invalid_argument naming the shard when the
/// shards are not in increasing first-frame order, a pose is not finite, a shard tracked no
/// frame, or a shard shares no tracked frame with the one before it (the overlap is too short or
/// tracking was lost there).
std::vector<ShardPlacement> joinShards(const std::vector<ShardTrack>& shards);

}  // namespace tessera::visual_slam
