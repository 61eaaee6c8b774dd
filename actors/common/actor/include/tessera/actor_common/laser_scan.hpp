// A msg::LaserScan as the core libraries read it: its beams as a grid::RangeScan (a view into the
// message, valid as long as the message) and its laser mounting (the laser's pose in the base
// frame: x, y [m], theta [rad]). Shared by every actor that hands scans to a core library.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_grid.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>

namespace tessera {

/// The scan's beams: ranges [m] viewed in place, first beam at angle_min [rad], angle_increment
/// [rad] apart, usable between range_min and range_max [m]. No field is checked here; the core
/// libraries judge NaN, infinite and out-of-range values.
inline grid::RangeScan rangeScanOf(msg::LaserScan::Reader scan) {
  return {view<float>(scan.getRanges()), scan.getAngleMin(), scan.getAngleIncrement(),
          scan.getRangeMin(), scan.getRangeMax()};
}

/// The laser's pose in the robot's base frame.
inline Pose2 laserMountOf(msg::LaserScan::Reader scan) {
  return {scan.getMountX(), scan.getMountY(), scan.getMountTheta()};
}

}  // namespace tessera
