// PackedRangeScan: a laser scan held compactly until it can be used, e.g. until a SLAM's final
// trajectory gives its pose at the end of a run (docs/algorithms.md#final-map-from-the-scans).
// Each range is 16 bits in units of range_max / 65000 (1.2 mm at an 80 m sensor, 0.5 mm at
// 30 m), half of a float scan. The unit is far below a grid cell: a map drawn from packed scans
// differs from one drawn from the originals only where a beam ends within half a unit of a cell
// border. A beam with no return (+inf or at/above range_max) and an invalid one (NaN, negative)
// keep their meaning exactly.
// Plain C++: no runtime or message types.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>

#include <cstdint>
#include <vector>

namespace tessera::mapping {

class PackedRangeScan {
 public:
  /// Packs `scan` taken at `stamp_ns` with the laser at `mount` on the robot. Throws
  /// std::invalid_argument for a non-finite or non-positive range_max (the unit needs it).
  PackedRangeScan(std::int64_t stamp_ns, const tessera::grid::RangeScan& scan,
                  const tessera::Pose2& mount);

  std::int64_t stampNs() const { return stamp_ns_; }
  const tessera::Pose2& mount() const { return mount_; }
  std::size_t beams() const { return codes_.size(); }
  /// Bytes held (for memory figures).
  std::size_t bytes() const { return sizeof(*this) + codes_.capacity() * sizeof(std::uint16_t); }

  /// The scan again; its ranges live in `buffer`, which must outlive the returned view.
  tessera::grid::RangeScan unpack(std::vector<float>& buffer) const;

 private:
  std::int64_t stamp_ns_;
  tessera::Pose2 mount_;
  float angle_min_, angle_increment_, range_min_, range_max_;
  std::vector<std::uint16_t> codes_;
};

}  // namespace tessera::mapping
