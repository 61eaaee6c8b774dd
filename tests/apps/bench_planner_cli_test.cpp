// `tessera bench planner` end to end on a small office: the JSON's fields and what must hold
// between the planners' figures (A* as cheap as Dijkstra, shortening never lengthens).
#include <nlohmann/json.hpp>

#include <map>
#include <string>

#include "../shared_data.hpp"
#include "cli_run.hpp"

using tessera::test::runCli;

TEST_CASE("bench planner reports every planner on a small office", "[bench_planner]") {
  const auto dir = tessera::test::scratchDir("bench_planner");
  const auto run =
      runCli("bench planner --json --cells 400 --distance 14 --pairs 2 --repeat 1 --seed 3", dir);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  for (const char* key :
       {"machine", "map_cells", "resolution_m", "pairs", "results", "landmarks", "landmarks_ms"})
    CHECK(j.contains(key));
  CHECK(j["map_cells"] == nlohmann::json::array({400, 400}));
  CHECK(j["resolution_m"].get<double>() == Approx(0.05));
  REQUIRE(j["pairs"].size() == 2);
  CHECK(j["pairs"][0]["straight_m"].get<double>() == Approx(14).margin(0.5));
  std::map<std::string, nlohmann::json> by_name;
  for (const auto& r : j["results"]) {
    for (const char* key : {"planner", "ms_median", "ms_p95", "length_m", "cost", "expanded"})
      CHECK(r.contains(key));
    CHECK(r["solved"] == 2);
    by_name[r["planner"].get<std::string>()] = r;
  }
  REQUIRE(by_name.size() == 5);
  const auto &dijkstra = by_name["dijkstra"], &astar = by_name["astar"],
             &landmarks = by_name["astar_landmarks"];
  CHECK(astar["cost"].get<double>() == Approx(dijkstra["cost"].get<double>()).epsilon(1e-12));
  CHECK(astar["expanded"].get<double>() < dijkstra["expanded"].get<double>());
  CHECK(astar["length_m"].get<double>() >= 14 - 0.5);
  // Landmark bounds: the same cost with fewer cells expanded; LOS and ACO start from that path.
  CHECK(j["landmarks"] == 8);
  CHECK(j["landmarks_ms"].get<double>() > 0);
  CHECK(landmarks["cost"].get<double>() == Approx(dijkstra["cost"].get<double>()).epsilon(1e-12));
  CHECK(landmarks["expanded"].get<double>() < astar["expanded"].get<double>());
  const double los = by_name["astar_los"]["length_m"].get<double>();
  CHECK(los <= landmarks["length_m"].get<double>() + 1e-9);
  CHECK(by_name["astar_los_aco"]["length_m"].get<double>() <= los + 1e-9);
}

TEST_CASE("bench planner names a bad option", "[bench_planner]") {
  const auto dir = tessera::test::scratchDir("bench_planner_bad");
  const auto zero = runCli("bench planner --repeat 0", dir);
  CHECK(zero.exit_code != 0);
  CHECK(zero.err.find("repeat") != std::string::npos);
  const auto far = runCli("bench planner --cells 200 --distance 20", dir);
  CHECK(far.exit_code != 0);
  CHECK(far.err.find("pair_distance") != std::string::npos);
  const auto many = runCli("bench planner --landmarks 17", dir);
  CHECK(many.exit_code != 0);
  CHECK(many.err.find("landmarks") != std::string::npos);
}
