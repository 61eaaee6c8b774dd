#include <tessera/visual_slam/shard_join.hpp>

#include <map>
#include <stdexcept>
#include <string>

namespace tessera::visual_slam {
namespace {

bool finite(const Pose3& p) {
  return p.t.allFinite() && p.q.coeffs().allFinite() && p.q.norm() > 0.5;
}

std::string shardName(std::size_t k) {
  return "shard " + std::to_string(k);
}

}  // namespace

std::vector<ShardPlacement> joinShards(const std::vector<ShardTrack>& shards) {
  std::vector<ShardPlacement> out;
  if (shards.empty()) throw std::invalid_argument("no shards to join");
  std::map<std::uint32_t, const ShardFramePose*> previous;
  for (std::size_t k = 0; k < shards.size(); ++k) {
    const ShardTrack& s = shards[k];
    if (k > 0 && s.first_frame <= shards[k - 1].first_frame)
      throw std::invalid_argument(
          shardName(k) + " starts at frame " + std::to_string(s.first_frame) + ", not after " +
          shardName(k - 1) + "'s first frame " + std::to_string(shards[k - 1].first_frame));
    if (s.poses.empty()) throw std::invalid_argument(shardName(k) + " tracked no frame");
    std::map<std::uint32_t, const ShardFramePose*> mine;
    for (const auto& p : s.poses) {
      if (!finite(p.pose))
        throw std::invalid_argument(shardName(k) + ": the pose of frame " +
                                    std::to_string(p.frame) + " is not finite");
      mine[p.frame] = &p;
    }
    ShardPlacement placement;
    placement.first_frame = s.first_frame;
    if (k > 0) {
      const ShardFramePose* a = nullptr;  // in shard k−1
      const ShardFramePose* b = nullptr;  // the same frame in shard k
      for (auto it = mine.lower_bound(s.first_frame); it != mine.end(); ++it) {
        const auto found = previous.find(it->first);
        if (found == previous.end()) continue;
        a = found->second;
        b = it->second;
        break;
      }
      if (!a)
        throw std::invalid_argument(
            shardName(k) + " shares no tracked frame with " + shardName(k - 1) + " (" +
            shardName(k - 1) + " tracked up to frame " + std::to_string(previous.rbegin()->first) +
            ", " + shardName(k) + " from frame " + std::to_string(mine.begin()->first) +
            "): give the shards more overlap");
      const ShardPlacement& before = out.back();
      placement.world_from_shard = before.world_from_shard * a->pose * b->pose.inverse();
      placement.stamp_offset_ns = before.stamp_offset_ns + a->stamp_ns - b->stamp_ns;
      placement.join_frame = a->frame;
    }
    out.push_back(placement);
    previous = std::move(mine);
  }
  return out;
}

}  // namespace tessera::visual_slam
