// KeptKeyframes: what a keyframe_poses message says about which keyframes the graph still holds
// (messages/schema/keyframe.capnp, docs/algorithms.md#lifelong-mapping). The message lists every
// keyframe the graph holds and keyframe ids only grow, so an id below the newest listed that is
// missing has left the graph (lifelong mode trimmed it, or it never entered): a consumer that
// holds something per keyframe (the loop detector's views, the front end's features, the
// mapper's clouds) may drop it. Ids above the newest listed are not decided yet.
// The one place this rule is written; the consumers walk only the ids they still hold, so the
// work per message is bounded by what is held, not by the ids in the message.
#pragma once

#include <tessera/msg/keyframe.capnp.h>

#include <cstdint>
#include <vector>

namespace tessera {

class KeptKeyframes {
 public:
  /// The ids of `poses` (every entry, whether or not its pose is readable: a bad pose does not
  /// mean the keyframe left the graph), sorted.
  explicit KeptKeyframes(msg::KeyframePoses::Reader poses);

  /// True when the message says keyframe `id` left the graph: below the newest listed id and
  /// not listed. False for every id when the message lists none.
  bool leftGraph(std::uint64_t id) const;
  /// True when `id` is listed.
  bool kept(std::uint64_t id) const;
  bool empty() const { return ids_.empty(); }
  std::size_t size() const { return ids_.size(); }

 private:
  std::vector<std::uint64_t> ids_;  ///< ascending
};

}  // namespace tessera
