// PoseHistory: a bounded, time-sorted record of planar poses (odometry, ground truth) that
// answers "where was the robot at time t" for sensor data stamped between two poses.
//
// Stamps are integer nanoseconds on the runtime clock; poses are in whatever frame the stream
// uses (odom, map). A lookup inside the history interpolates between the two poses that bracket
// the stamp (linear position, shortest-arc heading) unless they are more than max_gap_s apart;
// a stamp newer than every pose asks the caller to wait for more poses. Plain C++, not
// thread-safe.
#pragma once

#include <tessera/geometry/pose2.hpp>

#include <cstddef>
#include <cstdint>
#include <deque>

namespace tessera {

class PoseHistory {
 public:
  enum class Lookup {
    kWait,          ///< newer than every pose: a later pose may still bracket it
    kTooOld,        ///< older than every pose remembered
    kGap,           ///< the bracketing poses are more than max_gap_s apart
    kExact,         ///< a pose has exactly this stamp
    kInterpolated,  ///< between two poses
  };

  /// capacity >= 2 poses; max_gap_s > 0. Throws std::invalid_argument otherwise.
  PoseHistory(std::size_t capacity, double max_gap_s);

  /// Adds a pose (out-of-order stamps are inserted in place; an equal stamp replaces the old
  /// pose). Returns false, and keeps nothing, for a non-finite pose. The oldest poses are
  /// forgotten beyond the capacity.
  bool add(std::int64_t stamp_ns, const Pose2& pose);
  /// The pose at `stamp_ns` in `out` when the result is kExact or kInterpolated.
  Lookup at(std::int64_t stamp_ns, Pose2& out) const;

  bool empty() const { return poses_.empty(); }
  std::size_t size() const { return poses_.size(); }

 private:
  struct Entry {
    std::int64_t stamp_ns;
    Pose2 pose;
  };
  std::size_t capacity_;
  double max_gap_s_;
  std::deque<Entry> poses_;  // sorted by stamp
};

}  // namespace tessera
