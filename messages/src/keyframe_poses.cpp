// KeptKeyframes (see the header).
#include <tessera/messages/keyframe_poses.hpp>

#include <algorithm>

namespace tessera {

KeptKeyframes::KeptKeyframes(msg::KeyframePoses::Reader poses) {
  const auto list = poses.getPoses();
  ids_.reserve(list.size());
  for (const auto p : list) ids_.push_back(p.getId());
  // The schema says by increasing id; a sender that breaks it is read the same way.
  if (!std::is_sorted(ids_.begin(), ids_.end())) std::sort(ids_.begin(), ids_.end());
}

bool KeptKeyframes::leftGraph(std::uint64_t id) const {
  return !ids_.empty() && id < ids_.back() && !kept(id);
}

bool KeptKeyframes::kept(std::uint64_t id) const {
  return std::binary_search(ids_.begin(), ids_.end(), id);
}

}  // namespace tessera
