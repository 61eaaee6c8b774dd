// PosePairing: sensor items (scans, images) that wait, in arrival order and bounded, until a
// PoseHistory (odometry) can say where the robot was at their stamp; each paired item is handed
// to a callback with that pose, in order. Items that cannot be paired (older than the history,
// in a gap, pushed out of the full buffer, or still waiting at the end) are counted. Stamps in
// integer nanoseconds; poses in the history's frame. Header-only, not thread-safe.
#pragma once

#include <tessera/geometry/pose_history.hpp>

#include <cstddef>
#include <cstdint>
#include <deque>
#include <utility>

namespace tessera {

template <class Item>
class PosePairing {
 public:
  /// buffer >= 1 waiting items; history and max_gap_s as for PoseHistory (which throws).
  PosePairing(std::size_t buffer, std::size_t history, double max_gap_s)
      : history_(history, max_gap_s), buffer_(buffer < 1 ? 1 : buffer) {}

  /// Offers an item stamped `stamp_ns`; `use(item, pose)` runs now or from a later addPose().
  template <class Use>
  void addItem(Item item, std::int64_t stamp_ns, Use&& use) {
    Entry e{std::move(item), stamp_ns};
    // Items queued behind this one keep their order: only try it now if none is waiting.
    if (waiting_.empty() && tryUse(e, use)) return;
    if (waiting_.size() >= buffer_) {
      waiting_.pop_front();
      ++unpaired_;
    }
    waiting_.push_back(std::move(e));
  }

  /// Adds a pose and hands over the waiting items it pairs. False (nothing kept) for a
  /// non-finite pose.
  template <class Use>
  bool addPose(std::int64_t stamp_ns, const Pose2& pose, Use&& use) {
    if (!history_.add(stamp_ns, pose)) return false;
    while (!waiting_.empty() && tryUse(waiting_.front(), use)) waiting_.pop_front();
    return true;
  }

  /// No more poses will come: the items still waiting count as unpaired.
  void finish() {
    unpaired_ += waiting_.size();
    waiting_.clear();
  }

  std::uint64_t unpaired() const { return unpaired_; }
  std::size_t waiting() const { return waiting_.size(); }

 private:
  struct Entry {
    Item item;
    std::int64_t stamp_ns;
  };

  /// False: keep waiting. True: used, or counted as unpaired.
  template <class Use>
  bool tryUse(const Entry& e, Use& use) {
    Pose2 pose;
    switch (history_.at(e.stamp_ns, pose)) {
      case PoseHistory::Lookup::kWait:
        return false;
      case PoseHistory::Lookup::kTooOld:
      case PoseHistory::Lookup::kGap:
        ++unpaired_;
        return true;
      case PoseHistory::Lookup::kExact:
      case PoseHistory::Lookup::kInterpolated:
        break;
    }
    use(e.item, pose);
    return true;
  }

  PoseHistory history_;
  std::size_t buffer_;
  std::deque<Entry> waiting_;
  std::uint64_t unpaired_ = 0;
};

}  // namespace tessera
