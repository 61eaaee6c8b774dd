// Tests for the viewer actor's pieces a client reaches: the poses clients send as goals and
// initial poses (good forms, and truncated, malformed, NaN, empty input), and the live metrics
// message.
#include <tessera/viewer/viewer_actor.hpp>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <cmath>

// Everything in a namespace of its own: unity builds put test files together.
namespace viewer_actor_test {

using namespace tessera;
using namespace tessera::viewer;

TEST_CASE("client poses are read in the plain and the Foxglove/ROS forms", "[viewer]") {
  ClientPose p;
  CHECK(parseClientPose(R"({"x":1.5,"y":-2,"theta":0.5})", p).empty());
  CHECK(p.x == 1.5);
  CHECK(p.y == -2);
  CHECK(p.theta == 0.5);
  p = {};
  CHECK(parseClientPose(R"({"x":1,"y":2})", p).empty());
  CHECK(std::isnan(p.theta));  // heading does not matter
  p = {};
  const double yaw = 1.2;
  const std::string foxglove =
      R"({"timestamp":{"sec":1,"nsec":0},"frame_id":"map","pose":)"
      R"({"position":{"x":3,"y":4,"z":0},"orientation":{"x":0,"y":0,"z":)" +
      std::to_string(std::sin(yaw / 2)) + R"(,"w":)" + std::to_string(std::cos(yaw / 2)) + "}}}";
  CHECK(parseClientPose(foxglove, p).empty());
  CHECK(p.x == 3);
  CHECK(p.theta == Approx(yaw).margin(1e-5));
  p = {};
  CHECK(parseClientPose(R"({"position":{"x":5,"y":6}})", p).empty());
  CHECK(p.x == 5);
}

TEST_CASE("bad client poses are refused with the reason", "[viewer]") {
  ClientPose p;
  CHECK_THAT(parseClientPose("", p), Catch::Contains("JSON object"));
  CHECK_THAT(parseClientPose(R"({"x":1,"y")", p), Catch::Contains("JSON object"));  // truncated
  CHECK_THAT(parseClientPose("[1,2,3]", p), Catch::Contains("JSON object"));
  CHECK_THAT(parseClientPose(R"({"x":"1","y":2})", p), Catch::Contains("numbers"));
  CHECK_THAT(parseClientPose(R"({"x":1})", p), Catch::Contains("numbers"));
  CHECK_THAT(parseClientPose(R"({"x":NaN,"y":2})", p), Catch::Contains("JSON object"));
  CHECK_FALSE(parseClientPose(R"({"x":1e999,"y":2})", p).empty());  // out of double's range
  CHECK_THAT(parseClientPose(R"({"x":1,"y":2,"theta":"north"})", p), Catch::Contains("theta"));
  CHECK_THAT(parseClientPose(R"({"pose":{"orientation":{}}})", p), Catch::Contains("position"));
  CHECK_THAT(parseClientPose("{}", p), Catch::Contains("position"));
}

TEST_CASE("the metrics message gives rates over the last interval", "[viewer]") {
  RunSnapshot last;
  RunSnapshot now;
  now.wall_s = 1;
  now.sim_s = 4;
  now.actors.push_back({"slam", 10, 5, 0, 1, 3, 0.2});
  auto j = nlohmann::json::parse(metricsJson(now, last));
  CHECK(j["progress"].is_null());
  CHECK(j["actors"][0]["name"] == "slam");
  CHECK(j["actors"][0]["in_per_s"] == 0.0);  // no earlier figures yet
  now.wall_s = 3;
  now.progress = 0.25;
  now.actors[0] = {"slam", 30, 15, 2, 0, 3, 0.6};
  j = nlohmann::json::parse(metricsJson(now, last));
  CHECK(j["progress"] == 0.25);
  CHECK(j["actors"][0]["in_per_s"].get<double>() == Approx(10.0));
  CHECK(j["actors"][0]["busy_pct"].get<double>() == Approx(20.0));
  CHECK(j["actors"][0]["drops"] == 2);
}

}  // namespace viewer_actor_test
