#include <tessera/messages/keyframe_poses.hpp>
#include <tessera/messages/message.hpp>

#include <catch2/catch.hpp>

#include <cstdint>
#include <limits>
#include <vector>

using namespace tessera;

namespace {
Message<msg::KeyframePoses> posesOf(const std::vector<std::uint32_t>& ids) {
  return makeMessage<msg::KeyframePoses>([&](msg::KeyframePoses::Builder b) {
    auto list = b.initPoses(static_cast<unsigned>(ids.size()));
    for (unsigned i = 0; i < ids.size(); ++i) {
      list[i].setId(ids[i]);
      list[i].initPose().setQw(1.0);
    }
  });
}
}  // namespace

TEST_CASE("a keyframe missing below the newest listed id left the graph", "[messages]") {
  const auto m = posesOf({0, 3, 4, 7});
  const KeptKeyframes kept(*m);
  CHECK(kept.size() == 4);
  for (const std::uint64_t id : {0, 3, 4, 7}) {
    CHECK(kept.kept(id));
    CHECK_FALSE(kept.leftGraph(id));
  }
  for (const std::uint64_t id : {1, 2, 5, 6}) CHECK(kept.leftGraph(id));
  // Newer than anything listed: not decided yet (the graph has not seen it).
  CHECK_FALSE(kept.leftGraph(8));
  CHECK_FALSE(kept.leftGraph(std::numeric_limits<std::uint64_t>::max()));
}

TEST_CASE("an empty keyframe_poses message says no keyframe left", "[messages]") {
  const auto m = posesOf({});
  const KeptKeyframes kept(*m);
  CHECK(kept.empty());
  CHECK_FALSE(kept.leftGraph(0));
  CHECK_FALSE(kept.leftGraph(5));
}

TEST_CASE("keyframe ids out of order are read as if sorted, duplicates are harmless",
          "[messages]") {
  const auto m = posesOf({9, 2, 2, 5});
  const KeptKeyframes kept(*m);
  CHECK(kept.kept(2));
  CHECK(kept.kept(9));
  CHECK(kept.leftGraph(3));
  CHECK(kept.leftGraph(0));
  CHECK_FALSE(kept.leftGraph(9));
}

TEST_CASE("a listed keyframe with an unreadable pose is still kept", "[messages]") {
  auto m = makeMessage<msg::KeyframePoses>([](msg::KeyframePoses::Builder b) {
    auto list = b.initPoses(2);
    list[0].setId(1);
    list[0].initPose().setX(std::numeric_limits<double>::quiet_NaN());
    list[1].setId(4);
    list[1].initPose().setQw(1.0);
  });
  const KeptKeyframes kept(*m);
  CHECK(kept.kept(1));
  CHECK_FALSE(kept.leftGraph(1));
  CHECK(kept.leftGraph(2));
}
