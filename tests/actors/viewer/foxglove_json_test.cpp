// Tests for the Foxglove forms of Tessera messages: scans, grids, poses and paths in the
// well-known schemas, other types as their JSON, the frame transforms they imply, bad input.
#include <tessera/viewer/foxglove_json.hpp>
#include <tessera/viewer/foxglove_mcap.hpp>

#include <tessera/msg/navigation.capnp.h>
#include <tessera/messages/types.hpp>

#include <kj/encoding.h>
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <limits>

using namespace tessera;
using namespace tessera::viewer;
using nlohmann::json;

namespace {

template <class T, class F>
std::shared_ptr<const MessageStorage> build(F&& fill) {
  Loan<T> loan;
  fill(*loan);
  return std::move(loan).seal();
}

}  // namespace

TEST_CASE("a laser scan becomes foxglove.LaserScan with no-return beams at 0", "[viewer]") {
  const auto scan = build<msg::LaserScan>([](auto b) {
    setHeader(b.initHeader(), 2'500'000'001, "laser", 3);
    b.setAngleMin(-1.0f);
    b.setAngleIncrement(0.5f);
    auto r = b.initRanges(5);
    const float values[5] = {1.0f, std::numeric_limits<float>::infinity(), 2.5f,
                             std::numeric_limits<float>::quiet_NaN(), 4.0f};
    for (unsigned i = 0; i < 5; ++i) r.set(i, values[i]);
    b.setMountX(0.2f);
    b.setMountTheta(static_cast<float>(M_PI / 2));
  });
  const auto type = messageTypeOf<msg::LaserScan>().id;
  CHECK(foxgloveSchemaFor(type).name == "foxglove.LaserScan");
  CHECK(json::parse(foxgloveSchemaFor(type).data)["title"] == "foxglove.LaserScan");
  const json j = json::parse(foxgloveJson(type, *scan));
  CHECK(j["timestamp"]["sec"] == 2);
  CHECK(j["timestamp"]["nsec"] == 500'000'001);
  CHECK(j["frame_id"] == "laser");
  CHECK(j["start_angle"].get<double>() == Approx(-1.0));
  CHECK(j["end_angle"].get<double>() == Approx(1.0));
  CHECK(j["ranges"] == json::array({1.0, 0.0, 2.5, 0.0, 4.0}));
  // In its own frame: the mount is a transform (foxglove_mcap.hpp), not the scan's pose.
  CHECK(j["pose"]["position"]["x"].get<double>() == 0);
  CHECK(j["pose"]["orientation"]["w"].get<double>() == 1);
}

TEST_CASE("an occupancy grid becomes foxglove.Grid with its cells in base64", "[viewer]") {
  const auto grid = build<msg::OccupancyGrid>([](auto b) {
    setHeader(b.initHeader(), 0, "map", 0);
    b.setResolution(0.05f);
    b.setWidth(3);
    b.setHeight(2);
    auto o = b.initOrigin();
    o.setX(-1.0);
    o.setY(-2.0);
    auto c = b.initCells(6);
    const std::int8_t cells[6] = {-1, 0, 100, 50, 0, -1};
    for (unsigned i = 0; i < 6; ++i) c[i] = static_cast<kj::byte>(cells[i]);
  });
  const auto type = messageTypeOf<msg::OccupancyGrid>().id;
  CHECK(foxgloveSchemaFor(type).name == "foxglove.Grid");
  const json j = json::parse(foxgloveJson(type, *grid));
  CHECK(j["column_count"] == 3);
  CHECK(j["row_stride"] == 3);
  CHECK(j["cell_stride"] == 1);
  CHECK(j["fields"][0]["type"] == 2);
  CHECK(j["pose"]["position"]["x"].get<double>() == Approx(-1.0));
  const std::string data = j["data"].get<std::string>();
  const auto decoded = kj::decodeBase64(kj::ArrayPtr<const char>(data.data(), data.size()));
  REQUIRE(decoded.size() == 6);
  CHECK(static_cast<std::int8_t>(decoded[0]) == -1);
  CHECK(static_cast<std::int8_t>(decoded[2]) == 100);

  SECTION("a grid whose cells disagree with its size is an error, not a wrong picture") {
    const auto bad = build<msg::OccupancyGrid>([](auto b) {
      b.setWidth(4);
      b.setHeight(4);
      b.initCells(3);
    });
    CHECK_THROWS_WITH(foxgloveJson(type, *bad), Catch::Contains("3 cells"));
  }
}

TEST_CASE("poses and paths become foxglove.PoseInFrame and PosesInFrame", "[viewer]") {
  const auto path = build<msg::Path>([](auto b) {
    setHeader(b.initHeader(), 7, "map", 0);
    auto poses = b.initPoses(2);
    poses[1].initPose().setX(3.0);
    poses[1].getPose().setTheta(M_PI);
  });
  const auto type = messageTypeOf<msg::Path>().id;
  CHECK(foxgloveSchemaFor(type).name == "foxglove.PosesInFrame");
  const json j = json::parse(foxgloveJson(type, *path));
  REQUIRE(j["poses"].size() == 2);
  CHECK(j["poses"][1]["position"]["x"].get<double>() == Approx(3.0));
  CHECK(j["poses"][1]["orientation"]["z"].get<double>() == Approx(1.0));
  for (const auto t : {messageTypeOf<msg::PoseStamped>().id, messageTypeOf<msg::Odometry>().id,
                       messageTypeOf<msg::GroundTruthPose>().id})
    CHECK(foxgloveSchemaFor(t).name == "foxglove.PoseInFrame");
}

TEST_CASE("other message types are their own JSON, data fields in base64", "[viewer]") {
  const auto status = build<msg::NavStatus>([](auto b) {
    setHeader(b.initHeader(), 1, "map", 0);
    b.setGoalId(42);
    b.setReason("blocked");
    b.setDistanceRemaining(std::numeric_limits<double>::quiet_NaN());
  });
  const auto type = messageTypeOf<msg::NavStatus>().id;
  CHECK(foxgloveSchemaFor(type).name.empty());
  const json j = json::parse(foxgloveJson(type, *status));
  CHECK(j["goalId"] == "42");  // Cap'n Proto's JSON writes 64-bit integers as strings
  CHECK(j["reason"] == "blocked");
  CHECK(j.contains("distanceRemaining"));  // NaN still leaves valid JSON

  const auto blob = build<msg::Blob>([](auto b) {
    auto d = b.initPayload(3);
    d[0] = 'a';
    d[1] = 'b';
    d[2] = 'c';
  });
  CHECK(json::parse(foxgloveJson(messageTypeOf<msg::Blob>().id, *blob))["payload"] == "YWJj");
}

TEST_CASE("an unknown message type is named as such", "[viewer]") {
  CHECK_FALSE(knownMessageType(0x1234));
  CHECK_THROWS_WITH(foxgloveSchemaFor(0x1234), Catch::Contains("0x0000000000001234"));
  CHECK(knownMessageType(messageTypeOf<msg::LaserScan>().id));
}

TEST_CASE("odometry, scan mounts and map_to_odom give frame transforms; bad ones are skipped",
          "[viewer]") {
  const auto path = std::filesystem::temp_directory_path() / "tessera_foxglove_mcap_test.mcap";
  McapWriter writer(path.string());
  FoxgloveMcap foxglove(writer);
  const auto odom = foxglove.addTopic("odom", messageTypeOf<msg::Odometry>().id, "Odometry");
  const auto correction =
      foxglove.addTopic("map_to_odom", messageTypeOf<msg::PoseStamped>().id, "PoseStamped");
  const auto pose =
      foxglove.addTopic("localized_pose", messageTypeOf<msg::PoseStamped>().id, "PoseStamped");
  CHECK_THROWS_AS(foxglove.addTopic("mystery", 0x1234, "FromTheFuture"), MessageError);
  const auto odometry = [](double x) {
    return build<msg::Odometry>([x](auto b) {
      setHeader(b.initHeader(), 1, "odom", 0);
      b.setChildFrameId("base_link");
      b.initPose().setX(x);
    });
  };
  const auto stamped = build<msg::PoseStamped>([](auto b) {
    setHeader(b.initHeader(), 1, "map", 0);
    b.initPose().setY(2.0);
  });
  foxglove.write(odom, 1, *odometry(1.0));
  CHECK(foxglove.transforms() == 1);
  foxglove.write(odom, 2, *odometry(std::numeric_limits<double>::quiet_NaN()));
  CHECK(foxglove.transforms() == 1);  // the message is written, its transform is not
  foxglove.write(correction, 3, *stamped);
  CHECK(foxglove.transforms() == 2);
  foxglove.write(pose, 4, *stamped);
  CHECK(foxglove.transforms() == 2);
  writer.close();
  CHECK(writer.stats().messages == 4 + 2);
}
