// resource_monitor: rows on the run's clock, the counts it reads, and a write that fails.
#include <tessera/msg/keyframe.capnp.h>
#include <tessera/msg/sensor.capnp.h>
#include <tessera/msg/submap.capnp.h>
#include <tessera/evaluation/resource_monitor_actor.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>

#include "../../shared_data.hpp"

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

using namespace tessera;

namespace resource_monitor_test {

std::vector<std::string> lines(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::vector<std::string> out;
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

std::int64_t integer(const Summary& s, const std::string& key) {
  return std::get<std::int64_t>(s.at(key));
}

}  // namespace resource_monitor_test
using namespace resource_monitor_test;

TEST_CASE("resource_monitor writes a row every period of run time and one at stop",
          "[resource_monitor]") {
  const auto dir = test::scratchDir("resource_monitor");
  evaluation::ResourceMonitorOptions o;
  o.period_s = 10;
  ActorHarness h(std::make_unique<evaluation::ResourceMonitorActor>(o), dir.string());
  h.runUntilIdle();
  for (int k = 0; k < 25; ++k) {
    h.push<msg::LaserScan>("scan", [](auto&) {});
    if (k == 12) {
      h.push<msg::SubmapPoses>("submap_poses", [](auto& b) {
        auto poses = b.initPoses(2);
        poses[0].setId(0);
        poses[1].setId(7);
        auto t = b.initTrimmed(3);
        for (unsigned i = 0; i < 3; ++i) t.set(i, i + 1);
      });
    }
    h.runUntilIdle();
    h.advance(secondsToNanos(1.0));
  }
  // Before stop the file is still the temporary one: no half-written resources.csv.
  CHECK(!std::filesystem::exists(dir / "resources.csv"));
  h.stop();
  const auto rows = lines(dir / "resources.csv");
  // Header, t = 0, 10, 20 and the row at stop (t = 25).
  REQUIRE(rows.size() == 5);
  CHECK(rows[0] == "t_s,rss_mb,cpu_s,scans,submaps,graph_nodes,trimmed");
  CHECK(rows[1].rfind("0.000,", 0) == 0);
  CHECK(rows[2].rfind("10.000,", 0) == 0);
  CHECK(rows[4].rfind("25.000,", 0) == 0);
  // The last row: 25 scans, submaps made up to id 7, 2 nodes, 3 trimmed.
  CHECK(rows[4].substr(rows[4].size() - 9) == ",25,8,2,3");
  std::istringstream last(rows[4]);
  std::string t, rss;
  std::getline(last, t, ',');
  std::getline(last, rss, ',');
  CHECK(std::stod(rss) > 1.0);  // this test process is resident
  Summary s;
  h.actor().summarize(s);
  CHECK(integer(s, "rows") == 4);
  CHECK(integer(s, "scans") == 25);
}

TEST_CASE("resource_monitor counts keyframes from keyframe_poses in an RGB-D profile",
          "[resource_monitor][lifelong]") {
  const auto dir = test::scratchDir("resource_monitor_keyframes");
  evaluation::ResourceMonitorOptions o;
  o.period_s = 10;
  o.graph = false;
  o.keyframes = true;
  ActorHarness h(std::make_unique<evaluation::ResourceMonitorActor>(o), dir.string());
  h.runUntilIdle();
  // The graph holds keyframes 0, 5 and 9: ten made, seven gone (trimmed).
  h.push<msg::KeyframePoses>("keyframe_poses", [](auto& b) {
    auto poses = b.initPoses(3);
    poses[0].setId(0);
    poses[1].setId(5);
    poses[2].setId(9);
  });
  h.runUntilIdle();
  h.stop();
  const auto rows = lines(dir / "resources.csv");
  REQUIRE(rows.size() == 3);
  CHECK(rows[2].substr(rows[2].size() - 9) == ",0,10,3,7");
}

TEST_CASE("resource_monitor refuses bad options and reports a folder it cannot write",
          "[resource_monitor]") {
  evaluation::ResourceMonitorOptions o;
  o.period_s = 0;
  CHECK_THROWS_WITH(evaluation::ResourceMonitorActor(o), Catch::Contains("period_s"));
  o.period_s = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(evaluation::ResourceMonitorActor(o), Catch::Contains("period_s"));
  o = {};
  o.file = "";
  CHECK_THROWS_WITH(evaluation::ResourceMonitorActor(o), Catch::Contains("file"));
  o = {};
  o.keyframes = true;  // and graph, by default: two sources for the same counts
  CHECK_THROWS_WITH(evaluation::ResourceMonitorActor(o), Catch::Contains("graph and keyframes"));
  o = {};
  o.file = "no_such_folder/resources.csv";
  const auto dir = test::scratchDir("resource_monitor_bad");
  ActorHarness h(std::make_unique<evaluation::ResourceMonitorActor>(o), dir.string());
  h.runUntilIdle();
  h.stop();
  Summary s;
  h.actor().summarize(s);
  REQUIRE(s.count("error"));
  CHECK_THAT(std::get<std::string>(s.at("error")), Catch::Contains("no_such_folder"));
}
