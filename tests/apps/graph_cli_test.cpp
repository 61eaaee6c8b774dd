// `tessera graph optimize` end to end: a small g2o file written here, the CLI's JSON read back.
#include <tessera/pose_graph/pose_graph_io.hpp>

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <numbers>

#include "../shared_data.hpp"
#include "cli_run.hpp"

using tessera::test::runCli;

namespace {

/// A loop of 20 poses whose file poses carry a heading drift; its measurements are exact.
void writeDriftedLoop(const std::filesystem::path& path) {
  tessera::pose_graph::Graph2D g;  // node index = id
  const int n = 20;
  const double step = 2 * std::numbers::pi / n;
  Eigen::Vector3d at(0, 0, 0);
  const Eigen::Vector3d odo(1.0, 0.0, step);
  for (int i = 0; i < n; ++i) {
    g.addNode(i, at);
    const double th = at.z() + 0.02;  // drift in the start only
    at = {at.x() + std::cos(th) * odo.x(), at.y() + std::sin(th) * odo.x(), th + odo.z()};
  }
  for (int i = 0; i < n; ++i) {
    tessera::pose_graph::Edge2D e;
    e.from = i;
    e.to = (i + 1) % n;
    e.measurement = odo;  // a regular polygon: the closing edge n-1 -> 0 is the same step
    g.edges.push_back(e);
  }
  tessera::pose_graph::writeG2o(g, path);
}

}  // namespace

TEST_CASE("graph optimize closes a drifted loop and writes the result", "[graph_cli]") {
  const auto dir = tessera::test::scratchDir("graph_cli");
  writeDriftedLoop(dir / "loop.g2o");
  for (const std::string solver : {"sgd", "ceres", "sgd+ceres"}) {
    const auto run = runCli("graph optimize " + (dir / "loop.g2o").string() + " --solver " +
                                solver + " --out " + (dir / "out.g2o").string() + " --json",
                            dir);
    REQUIRE(run.exit_code == 0);
    const auto j = nlohmann::json::parse(run.out);
    for (const char* key :
         {"nodes", "edges", "initial_chi2", "final_chi2", "iterations", "seconds", "solver"})
      CHECK(j.contains(key));
    CHECK(j["nodes"] == 20);
    CHECK(j["edges"] == 20);
    CHECK(j["solver"] == solver);
    CHECK(j["initial_chi2"].get<double>() > 1.0);
    if (solver == "sgd") {
      CHECK(j["final_chi2"].get<double>() < 0.5 * j["initial_chi2"].get<double>());
    } else {
      CHECK(j["final_chi2"].get<double>() < 1e-9);
      // The written file holds the optimised poses: its χ² is the reported final one.
      const auto back = tessera::pose_graph::readPoseGraph2D(dir / "out.g2o");
      const Eigen::Vector3d p10 = back.poses[back.index(10)];
      CHECK(std::hypot(p10.x(), p10.y()) > 5.0);  // across the polygon, not near the start
    }
  }
}

TEST_CASE("graph optimize from odometry ignores the file poses", "[graph_cli]") {
  const auto dir = tessera::test::scratchDir("graph_cli_odo");
  writeDriftedLoop(dir / "loop.g2o");
  const auto run = runCli(
      "graph optimize " + (dir / "loop.g2o").string() + " --init odometry --solver ceres --json",
      dir);
  REQUIRE(run.exit_code == 0);
  // Chaining the exact odometry closes the loop exactly: nothing left to optimise.
  CHECK(nlohmann::json::parse(run.out)["initial_chi2"].get<double>() < 1e-9);
}

TEST_CASE("graph optimize names the bad argument", "[graph_cli]") {
  const auto dir = tessera::test::scratchDir("graph_cli_err");
  writeDriftedLoop(dir / "loop.g2o");
  const std::string in = (dir / "loop.g2o").string();
  auto run = runCli("graph optimize " + in + " --solver newton", dir);
  CHECK(run.exit_code == 2);
  CHECK_THAT(run.err, Catch::Contains("--solver") && Catch::Contains("sgd+ceres"));
  run = runCli("graph optimize " + in + " --init guess", dir);
  CHECK(run.exit_code == 2);
  CHECK_THAT(run.err, Catch::Contains("--init"));
  run = runCli("graph optimize " + (dir / "missing.g2o").string(), dir);
  CHECK(run.exit_code == 2);
  CHECK_THAT(run.err, Catch::Contains("missing.g2o"));
  std::ofstream(dir / "bad.g2o") << "VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n";
  run = runCli("graph optimize " + (dir / "bad.g2o").string(), dir);
  CHECK(run.exit_code == 1);
  CHECK_THAT(run.err, Catch::Contains("bad.g2o:2"));
}

TEST_CASE("graph optimize on intel.g2o reaches the g2o optimum", "[graph_cli][data]") {
  TESSERA_SHARED_DATA(path, "posegraph-g2o/intel.g2o");
  const auto dir = tessera::test::scratchDir("graph_cli_intel");
  const auto run = runCli("graph optimize " + path.string() + " --json", dir);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  CHECK(j["nodes"] == 1728);
  CHECK(j["edges"] == 2512);
  CHECK_THAT(j["initial_chi2"].get<double>(), Catch::Matchers::WithinRel(551.7357, 1e-6));
  CHECK_THAT(j["final_chi2"].get<double>(), Catch::Matchers::WithinRel(45.004696, 1e-6));
}
