// Inputs for navigation actor tests through the mock-mailbox harness: a walled room as a map
// message, poses, odometry and goals, and the options those tests share.
#pragma once

#include <tessera/msg/navigation.capnp.h>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/navigation/navigation_actor.hpp>
#include <tessera/runtime/harness.hpp>

#include <cstdint>
#include <string>

namespace tessera::test::nav {

struct Room {
  std::string topic = "map";
  bool unknown_square = false;  ///< an unknown 1 m square at (6-7, 3-4)
  bool block = false;           ///< a 0.5 m obstacle at (3-3.5, 6-6.5)
};

/// A 10 m x 8 m room at 0.1 m with a 0.2 m wall all round, as a map message on room.topic.
inline void pushRoom(ActorHarness& h, const Room& room = {}) {
  const int w = 100, hgt = 80;
  h.push<msg::OccupancyGrid>(room.topic, [&](auto& b) {
    setHeader(b.initHeader(), 0, "map", 0);
    b.setResolution(0.1f);
    b.setWidth(w);
    b.setHeight(hgt);
    writePose(b.initOrigin(), Pose2());
    auto cells = mutableViewInt8(b.initCells(w * hgt));
    for (int r = 0; r < hgt; ++r)
      for (int c = 0; c < w; ++c) {
        const bool wall = r < 2 || c < 2 || r >= hgt - 2 || c >= w - 2;
        const bool unknown = room.unknown_square && c >= 60 && c < 70 && r >= 30 && r < 40;
        const bool blocked = room.block && c >= 30 && c < 35 && r >= 60 && r < 65;
        cells[static_cast<std::size_t>(r * w + c)] = static_cast<std::int8_t>(wall || blocked ? 100
                                                                              : unknown       ? -1
                                                                                              : 0);
      }
  });
}

inline void pushPose(ActorHarness& h, Nanos t, const Pose2& p) {
  h.push<msg::PoseStamped>("pose", [&](auto& b) {
    setHeader(b.initHeader(), t, "map", 0);
    writePose(b.initPose(), p);
  });
}

inline void pushOdom(ActorHarness& h, Nanos t, const Pose2& p, double v, double w) {
  h.push<msg::Odometry>("odom", [&](auto& b) {
    setHeader(b.initHeader(), t, "odom", 0);
    b.setChildFrameId("base_link");
    writePose(b.initPose(), p);
    b.initTwist().setVx(v);
    b.getTwist().setOmega(w);
  });
}

inline void pushGoal(ActorHarness& h, std::uint64_t id, const Pose2& g,
                     const std::string& frame = "map") {
  h.push<msg::NavGoal>("goal", [&](auto& b) {
    setHeader(b.initHeader(), h.now(), frame, 0);
    writePose(b.initPose(), g);
    b.setId(id);
    b.setToleranceXy(0);
    b.setToleranceYaw(0);
  });
}

/// The robot standing at `start` at time 0: a pose and odometry, handled.
inline void placeRobot(ActorHarness& h, const Pose2& start) {
  pushPose(h, 0, start);
  pushOdom(h, 0, start, 0, 0);
  h.runUntilIdle();
}

/// The room tests' navigator: map only (no laser), a 0.2 m robot inflated to 0.5 m.
inline navigation::NavigationActorOptions roomOptions() {
  navigation::NavigationActorOptions o;
  o.use_scan = false;
  o.inflation.inscribed_radius = 0.2;
  o.inflation.inflation_radius = 0.5;
  return o;
}

}  // namespace tessera::test::nav
