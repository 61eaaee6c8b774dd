// A finished msg::Submap with a tiny blank grid, for the global-level actor tests that only
// care about its id, origin, stamp and trajectory.
#pragma once

#include <tessera/msg/submap.capnp.h>
#include <tessera/geometry/pose2.hpp>
#include <tessera/messages/types.hpp>

#include <cstdint>

namespace tessera::test {

inline void fillSubmap(msg::Submap::Builder b, int id, const tessera::Pose2& origin,
                       std::int64_t stamp) {
  setHeader(b.initHeader(), stamp, "map", 0);
  b.setId(static_cast<std::uint32_t>(id));
  auto g = b.initGrid();
  g.setResolution(0.1f);
  g.setWidth(2);
  g.setHeight(2);
  writePose(g.initOrigin(), tessera::Pose2{0, 0, 0});
  g.initCells(4);
  writePose(b.initGlobalPose(), tessera::Pose2{origin.x, origin.y, origin.theta});
  b.setFinished(true);
}

}  // namespace tessera::test
