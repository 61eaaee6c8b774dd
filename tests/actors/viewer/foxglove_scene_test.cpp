// Tests for the Foxglove forms of the display messages: the dynamic window's arcs and camera
// footprints as foxglove.SceneUpdate, a 3D map preview as foxglove.PointCloud; malformed ones are
// refused with the reason.
#include <tessera/viewer/foxglove_json.hpp>

#include <tessera/msg/camera.capnp.h>
#include <tessera/msg/cloud.capnp.h>
#include <tessera/msg/landmark.capnp.h>
#include <tessera/msg/lines.capnp.h>
#include <tessera/msg/navigation.capnp.h>
#include <tessera/msg/submap.capnp.h>
#include <tessera/messages/types.hpp>

#include <kj/encoding.h>
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

// Everything in a namespace of its own: unity builds put test files together.
namespace foxglove_scene_test {

using namespace tessera;
using namespace tessera::viewer;
using nlohmann::json;

template <class T, class F>
std::shared_ptr<const MessageStorage> make(F&& fill) {
  Loan<T> loan;
  fill(*loan);
  return std::move(loan).seal();
}

void setArc(msg::LocalPlan::Arc::Builder a, float v, float w, bool admissible, float score,
            std::vector<float> xy) {
  a.setV(v);
  a.setW(w);
  a.setAdmissible(admissible);
  a.setScore(score);
  auto l = a.initXy(static_cast<unsigned>(xy.size()));
  for (unsigned i = 0; i < xy.size(); ++i) l.set(i, xy[i]);
}

TEST_CASE("a local plan becomes one scene entity with a line per arc, the chosen one last",
          "[viewer]") {
  const auto type = messageTypeOf<msg::LocalPlan>().id;
  CHECK(foxgloveSchemaFor(type).name == "foxglove.SceneUpdate");
  CHECK(json::parse(foxgloveSchemaFor(type).data)["title"] == "foxglove.SceneUpdate");
  const auto plan = make<msg::LocalPlan>([](auto b) {
    setHeader(b.initHeader(), 2'500'000'000, "map", 0);
    b.setGoalId(7);
    b.initCommand().setVx(0.4);
    b.setChosen(1);
    auto arcs = b.initArcs(3);
    setArc(arcs[0], 0.0f, 0.5f, false, 0.0f, {1, 1, 1.1f, 1.2f});
    setArc(arcs[1], 0.4f, 0.0f, true, 0.9f, {1, 1, 1.5f, 1, 2, 1});
    setArc(arcs[2], 0.2f, 1.0f, true, 0.3f, {1, 1, 1.2f, 1.2f});
  });
  const json j = json::parse(foxgloveJson(type, *plan));
  CHECK(j["deletions"].empty());
  REQUIRE(j["entities"].size() == 1);
  const json& e = j["entities"][0];
  CHECK(e["id"] == "local_plan");
  CHECK(e["frame_id"] == "map");
  CHECK(e["timestamp"]["sec"] == 2);
  CHECK(e["timestamp"]["nsec"] == 500'000'000);
  for (const char* list : {"arrows", "cubes", "spheres", "cylinders", "triangles", "models"})
    CHECK(e[list].is_array());
  REQUIRE(e["lines"].size() == 4);  // three arcs and the chosen one again, on top
  const json& chosen = e["lines"][3];
  CHECK(chosen["type"] == 0);
  REQUIRE(chosen["points"].size() == 3);
  CHECK(chosen["points"][2]["x"].get<double>() == Approx(2.0));
  CHECK(chosen["thickness"].get<double>() > e["lines"][1]["thickness"].get<double>());
  // Inadmissible arcs are faint; the best admissible one is the brightest.
  CHECK(e["lines"][0]["color"]["a"].get<double>() < e["lines"][1]["color"]["a"].get<double>());
  CHECK(e["lines"][1]["color"]["r"].get<double>() > e["lines"][2]["color"]["r"].get<double>());

  // No arcs: the goal ended, the entity goes.
  const auto ended = make<msg::LocalPlan>([](auto b) {
    setHeader(b.initHeader(), 3'000'000'000, "map", 1);
    b.setChosen(-1);
  });
  const json d = json::parse(foxgloveJson(type, *ended));
  CHECK(d["entities"].empty());
  REQUIRE(d["deletions"].size() == 1);
  CHECK(d["deletions"][0]["id"] == "local_plan");
  CHECK(d["deletions"][0]["type"] == 0);
}

TEST_CASE("a local plan with non-finite points or a chosen index out of range still draws",
          "[viewer]") {
  const auto plan = make<msg::LocalPlan>([](auto b) {
    setHeader(b.initHeader(), 0, "map", 0);
    b.setChosen(5);  // no such arc: nothing is drawn as chosen
    auto arcs = b.initArcs(1);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    setArc(arcs[0], 0.1f, 0, true, nan, {0, 0, nan, 1, 1, 1, 2});  // odd count: last dropped
  });
  const json j = json::parse(foxgloveJson(messageTypeOf<msg::LocalPlan>().id, *plan));
  REQUIRE(j["entities"][0]["lines"].size() == 1);
  CHECK(j["entities"][0]["lines"][0]["points"].size() == 2);
}

TEST_CASE("camera footprints become an entity per camera with its polygon and a label",
          "[viewer]") {
  const auto type = messageTypeOf<msg::CameraFootprints>().id;
  CHECK(foxgloveSchemaFor(type).name == "foxglove.SceneUpdate");
  const auto fp = make<msg::CameraFootprints>([](auto b) {
    setHeader(b.initHeader(), 0, "map", 0);
    auto cams = b.initCameras(2);
    cams[0].setCameraId(3);
    auto xy = cams[0].initXy(8);
    const double square[] = {0, 0, 2, 0, 2, 2, 0, 2};
    for (unsigned i = 0; i < 8; ++i) xy.set(i, square[i]);
    cams[1].setCameraId(4);
    cams[1].setCalibrated(true);
    cams[1].initXy(0);
  });
  const json j = json::parse(foxgloveJson(type, *fp));
  REQUIRE(j["entities"].size() == 2);
  const json& e = j["entities"][0];
  CHECK(e["id"] == "camera_3");
  REQUIRE(e["lines"].size() == 1);
  CHECK(e["lines"][0]["type"] == 1);  // a closed loop
  CHECK(e["lines"][0]["points"].size() == 4);
  REQUIRE(e["texts"].size() == 1);
  CHECK(e["texts"][0]["text"] == "camera 3");
  CHECK(e["texts"][0]["pose"]["position"]["x"].get<double>() == Approx(1.0));
  CHECK(j["entities"][1]["texts"].empty());  // no polygon, no label
  CHECK(j["entities"][0]["lines"][0]["color"] != j["entities"][1]["lines"][0]["color"]);

  const auto odd = make<msg::CameraFootprints>([](auto b) {
    auto cams = b.initCameras(1);
    cams[0].setCameraId(9);
    cams[0].initXy(3);
  });
  CHECK_THROWS_WITH(foxgloveJson(type, *odd),
                    Catch::Contains("camera 9") && Catch::Contains("odd number"));
}

TEST_CASE("a point cloud becomes foxglove.PointCloud, packed with colour when it has one",
          "[viewer]") {
  const auto type = messageTypeOf<msg::PointCloud>().id;
  CHECK(foxgloveSchemaFor(type).name == "foxglove.PointCloud");
  const std::vector<float> pts = {1, 2, 3, -1, -2, 0.5f};
  auto cloud = [&](unsigned count, std::size_t xyz_bytes, std::size_t rgb_bytes) {
    return make<msg::PointCloud>([&](auto b) {
      setHeader(b.initHeader(), 5, "world", 0);
      b.setCount(count);
      b.setVoxelSize(0.05f);
      auto d = b.initXyz(static_cast<unsigned>(xyz_bytes));
      std::memcpy(d.begin(), pts.data(), std::min(xyz_bytes, pts.size() * 4));
      auto c = b.initRgb(static_cast<unsigned>(rgb_bytes));
      for (std::size_t i = 0; i < rgb_bytes; ++i) c[i] = static_cast<kj::byte>(10 * i);
    });
  };
  const json j = json::parse(foxgloveJson(type, *cloud(2, 24, 0)));
  CHECK(j["frame_id"] == "world");
  CHECK(j["point_stride"] == 12);
  REQUIRE(j["fields"].size() == 3);
  CHECK(j["fields"][2]["name"] == "z");
  CHECK(j["fields"][2]["type"] == 7);
  const std::string b64 = j["data"].get<std::string>();
  const auto raw = kj::decodeBase64(kj::ArrayPtr<const char>(b64.data(), b64.size()));
  REQUIRE(raw.size() == 24);
  float z1;
  std::memcpy(&z1, raw.begin() + 20, 4);
  CHECK(z1 == 0.5f);

  const json c = json::parse(foxgloveJson(type, *cloud(2, 24, 6)));
  CHECK(c["point_stride"] == 16);
  CHECK(c["fields"].size() == 6);
  const std::string b64c = c["data"].get<std::string>();
  const auto packed = kj::decodeBase64(kj::ArrayPtr<const char>(b64c.data(), b64c.size()));
  REQUIRE(packed.size() == 32);
  float x1;
  std::memcpy(&x1, packed.begin() + 16, 4);
  CHECK(x1 == -1.0f);
  CHECK(packed[16 + 12] == 30);  // the second point's red
  CHECK(packed[16 + 15] == 255);

  CHECK_THROWS_WITH(foxgloveJson(type, *cloud(3, 24, 0)),
                    Catch::Contains("3 points carries 24 xyz bytes"));
  CHECK_THROWS_WITH(foxgloveJson(type, *cloud(2, 24, 5)), Catch::Contains("5 rgb bytes"));
  CHECK(json::parse(foxgloveJson(type, *cloud(0, 0, 0)))["data"] == "");  // empty is fine
}

TEST_CASE("submap poses become an arrow and a label per submap, replacing the last set",
          "[viewer]") {
  const auto type = messageTypeOf<msg::SubmapPoses>().id;
  CHECK(foxgloveSchemaFor(type).name == "foxglove.SceneUpdate");
  const auto poses = make<msg::SubmapPoses>([](auto b) {
    setHeader(b.initHeader(), 0, "map", 0);
    auto p = b.initPoses(3);
    p[0].setId(0);
    p[0].initPose();
    p[1].setId(4);
    p[1].initPose().setX(2.0);
    p[1].getPose().setTheta(M_PI / 2);
    p[2].setId(5);
    p[2].initPose().setX(std::numeric_limits<double>::quiet_NaN());  // skipped
  });
  const json j = json::parse(foxgloveJson(type, *poses));
  REQUIRE(j["deletions"].size() == 1);
  CHECK(j["deletions"][0]["type"] == 1);  // all: the message holds every submap
  REQUIRE(j["entities"].size() == 2);
  const json& e = j["entities"][1];
  CHECK(e["id"] == "submap_4");
  CHECK(e["metadata"][0]["key"] == "submap_id");
  CHECK(e["metadata"][0]["value"] == "4");
  REQUIRE(e["arrows"].size() == 1);
  CHECK(e["arrows"][0]["pose"]["position"]["x"].get<double>() == Approx(2.0));
  CHECK(e["arrows"][0]["pose"]["orientation"]["z"].get<double>() == Approx(std::sqrt(0.5)));
  CHECK(e["texts"][0]["text"] == "4");
  CHECK(e["lines"].empty());
}

TEST_CASE("landmark and line maps become spheres and a line list", "[viewer]") {
  const auto landmarks = make<msg::LandmarkMap>([](auto b) {
    setHeader(b.initHeader(), 0, "map", 0);
    auto l = b.initLandmarks(3);
    l[0].setId(7);
    l[0].setX(1);
    l[0].setY(2);
    l[1].setId(8);
    l[1].setX(std::numeric_limits<double>::infinity());  // skipped
    l[2].setId(9);
    l[2].setX(-1);
  });
  const auto lt = messageTypeOf<msg::LandmarkMap>().id;
  CHECK(foxgloveSchemaFor(lt).name == "foxglove.SceneUpdate");
  const json l = json::parse(foxgloveJson(lt, *landmarks));
  const json& le = l["entities"][0];
  CHECK(le["id"] == "landmarks");
  REQUIRE(le["spheres"].size() == 2);
  CHECK(le["spheres"][0]["pose"]["position"]["y"].get<double>() == Approx(2.0));
  CHECK(le["metadata"][0]["value"] == "7,9");

  const auto lines = make<msg::LineMap>([](auto b) {
    setHeader(b.initHeader(), 0, "map", 0);
    auto f = b.initLines(2);
    f[0].setX0(0);
    f[0].setY0(0);
    f[0].setX1(3);
    f[0].setY1(0);
    f[1].setX0(std::numeric_limits<double>::quiet_NaN());  // skipped
  });
  const auto nt = messageTypeOf<msg::LineMap>().id;
  const json n = json::parse(foxgloveJson(nt, *lines));
  const json& line = n["entities"][0]["lines"][0];
  CHECK(line["type"] == 2);  // a line list: pairs of points
  REQUIRE(line["points"].size() == 2);
  CHECK(line["points"][1]["x"].get<double>() == Approx(3.0));
}

}  // namespace foxglove_scene_test
