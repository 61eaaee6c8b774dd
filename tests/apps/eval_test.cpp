// `tessera eval ...` end to end: runs the built CLI on files written here and reads its JSON.
#include <tessera/evaluation/landmark_io.hpp>
#include <tessera/geometry/pose2.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/pose_graph/pose_graph_io.hpp>

#include <nlohmann/json.hpp>

#include <sys/wait.h>

#include <cstdio>
#include <fstream>
#include <numbers>
#include <sstream>

#include "../shared_data.hpp"
#include "cli_run.hpp"

namespace fs = std::filesystem;
using namespace tessera::evaluation;
using namespace tessera::mapping;
using namespace tessera;
using tessera::test::CliRun;
using tessera::test::runCli;

namespace {

std::vector<TumPose> square(double side, int per_side) {
  std::vector<TumPose> out;
  const std::int64_t dt = 100'000'000;  // 10 Hz
  double x = 0, y = 0, th = 0;
  for (int s = 0; s < 4; ++s) {
    for (int k = 0; k < per_side; ++k) {
      out.push_back(
          TumPose::fromPlanar(static_cast<std::int64_t>(out.size()) * dt, Pose2(x, y, th)));
      x += side / per_side * std::cos(th);
      y += side / per_side * std::sin(th);
    }
    th += std::numbers::pi / 2;
  }
  return out;
}

}  // namespace

TEST_CASE("tessera eval ate/rpe print one JSON object with the documented keys", "[eval][cli]") {
  const auto dir = tessera::test::scratchDir("eval_cli");
  const auto reference = square(4, 40);
  auto estimate = reference;
  // The estimate in another world frame (rotated 30°, shifted): ATE aligns it away.
  const Pose2 frame(3, -1, std::numbers::pi / 6);
  for (auto& p : estimate) p = TumPose::fromPlanar(p.stamp_ns, frame * p.planar());
  writeTum(dir / "ref.tum", reference);
  writeTum(dir / "est.tum", estimate);

  const std::string files =
      " --estimate " + (dir / "est.tum").string() + " --reference " + (dir / "ref.tum").string();
  const CliRun ate = runCli("eval ate" + files + " --json", dir);
  INFO(ate.err);
  REQUIRE(ate.exit_code == 0);
  const auto j = nlohmann::json::parse(ate.out);
  for (const char* key : {"pairs", "rmse_m", "mean_m", "median_m", "max_m"}) CHECK(j.contains(key));
  CHECK(j["pairs"] == 160);
  CHECK(j["rmse_m"].get<double>() < 1e-9);
  CHECK(j["mode"] == "se2");
  CHECK_THAT(ate.err, Catch::Contains("rmse"));  // the human summary went to stderr

  const CliRun rpe = runCli("eval rpe" + files + " --json --delta 10 --delta-unit f", dir);
  REQUIRE(rpe.exit_code == 0);
  const auto r = nlohmann::json::parse(rpe.out);
  for (const char* key : {"pairs", "rmse_m", "mean_m", "median_m", "max_m", "rot_rmse_deg"})
    CHECK(r.contains(key));
  CHECK(r["pairs"] == 150);
  CHECK(r["rot_rmse_deg"].get<double>() < 1e-6);

  // Without --json: the summary on stdout, with units.
  const CliRun human = runCli("eval ate" + files, dir);
  REQUIRE(human.exit_code == 0);
  CHECK_THAT(human.out, Catch::Contains("pairs") && Catch::Contains(" m"));
}

TEST_CASE("tessera eval relations and landmarks report their keys", "[eval][cli]") {
  const auto dir = tessera::test::scratchDir("eval_cli_rel");
  const auto traj = square(4, 40);
  writeTum(dir / "traj.tum", traj);
  {
    // One exact relation (1 s = 10 poses straight ahead, 0.1 m each) and one 0.5 m too long.
    std::ofstream rel(dir / "r.relations");
    rel << "# t1 t2 dx dy dz roll pitch yaw\n"
        << "0.0 1.0 1.0 0 0 0 0 0\n"
        << "0.5 1.5 1.5 0 0 0 0 0\n"
        << "100 101 1 0 0 0 0 0\n";  // after the end of the trajectory
  }
  const CliRun rel = runCli("eval relations --trajectory " + (dir / "traj.tum").string() +
                                " --relations " + (dir / "r.relations").string() + " --json",
                            dir);
  INFO(rel.err);
  REQUIRE(rel.exit_code == 0);
  const auto j = nlohmann::json::parse(rel.out);
  CHECK(j["relations"] == 3);
  CHECK(j["matched"] == 2);
  CHECK(j["trans_mean_m"].get<double>() == Approx(0.25));
  CHECK(j["trans2_mean"].get<double>() == Approx(0.125));
  CHECK(j["trans_std_m"].get<double>() == Approx(std::sqrt(0.125)));
  for (const char* key : {"trans2_std", "rot_mean_deg", "rot_std_deg", "rot2_mean", "rot2_std"})
    CHECK(j.contains(key));

  writeLandmarks(dir / "a.txt", {{1, {0, 0}}, {2, {1, 0}}, {3, {0, 2}}});
  writeLandmarks(dir / "b.txt", {{1, {5, 5}}, {2, {5, 6}}, {3, {3, 5}}, {4, {0, 0}}});
  const CliRun lm = runCli("eval landmarks --estimate " + (dir / "a.txt").string() +
                               " --reference " + (dir / "b.txt").string() + " --json",
                           dir);
  REQUIRE(lm.exit_code == 0);
  const auto l = nlohmann::json::parse(lm.out);
  CHECK(l["pairs"] == 3);
  CHECK(l["rmse_m"].get<double>() < 1e-9);
  CHECK(l.contains("median_m"));
}

TEST_CASE("tessera eval relations --max-speed and --bins report the split and the bins",
          "[eval][cli]") {
  const auto dir = tessera::test::scratchDir("eval_cli_bins");
  writeTum(dir / "traj.tum", square(4, 40));  // 1 m/s along the first side (0-4 s)
  {
    std::ofstream rel(dir / "r.relations");
    rel << "0.0 1.0 1.0 0 0 0 0 0\n"     // exact
        << "0.5 1.5 1.5 0 0 0 0 0\n"     // 1.5 m/s: too fast; 0.5 m off
        << "2.0 3.0 1.0 0 0 0 0 0\n"     // exact
        << "2.5 3.5 1.0 0 0 0 0 0.1\n";  // 0.1 rad off, no translation error
  }
  const std::string base = "eval relations --trajectory " + (dir / "traj.tum").string() +
                           " --relations " + (dir / "r.relations").string();
  const CliRun plain = runCli(base + " --json", dir);
  REQUIRE(plain.exit_code == 0);
  const auto p = nlohmann::json::parse(plain.out);
  CHECK_FALSE(p.contains("consistent"));
  CHECK_FALSE(p.contains("bins"));

  const CliRun run = runCli(base + " --json --max-speed 1.2 --bins 2", dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  // The headline is unchanged by the options.
  for (const char* key : {"matched", "trans_mean_m", "trans_std_m", "rot_mean_deg", "rot2_mean"})
    CHECK(j[key] == p[key]);
  CHECK(j["trans_mean_m"].get<double>() == Approx(0.125));
  CHECK(j["inconsistent_count"] == 1);
  const auto& c = j["consistent"];
  CHECK(c["max_speed"].get<double>() == 1.2);
  CHECK(c["count"] == 3);
  CHECK(c["trans_mean_m"].get<double>() == Approx(0).margin(1e-9));
  CHECK(c["rot_mean_deg"].get<double>() == Approx(0.1 * 180 / std::numbers::pi / 3));
  for (const char* key : {"trans_std_m", "trans2_mean", "rot_std_deg", "rot2_mean"})
    CHECK(c.contains(key));
  CHECK(j["bin_s"].get<double>() == 2);
  REQUIRE(j["bins"].size() == 2);
  CHECK(j["bins"][0]["start_s"].get<double>() == 0);
  CHECK(j["bins"][0]["count"] == 2);
  CHECK(j["bins"][0]["trans_mean_m"].get<double>() == Approx(0.25));
  CHECK(j["bins"][0]["rot_mean_deg"].get<double>() == Approx(0).margin(1e-9));
  CHECK(j["bins"][1]["start_s"].get<double>() == 2);
  CHECK(j["bins"][1]["count"] == 2);
  CHECK(j["bins"][1]["trans_mean_m"].get<double>() == Approx(0).margin(1e-9));
  CHECK(j["bins"][1]["rot_mean_deg"].get<double>() == Approx(0.05 * 180 / std::numbers::pi));

  // The human summary: the split as extra rows, and the table.
  const CliRun human = runCli(base + " --max-speed 1.2 --bins 2", dir);
  REQUIRE(human.exit_code == 0);
  CHECK_THAT(human.out, Catch::Contains("3 of 4 matched (1 faster than 1.20 m/s") &&
                            Catch::Contains("start s") && Catch::Contains("0.2500"));

  // Bad values are usage errors naming the option.
  for (const char* bad : {" --bins -1", " --bins 0", " --bins nan", " --bins 1e-12",
                          " --max-speed -1", " --max-speed nan"}) {
    const CliRun e = runCli(base + bad, dir);
    INFO(bad << ": " << e.err);
    CHECK(e.exit_code == 2);
    CHECK_THAT(e.err,
               Catch::Contains(std::string(bad).substr(1, std::string(bad).find(' ', 1) - 1)));
  }
}

TEST_CASE("tessera eval relations --plot writes an SVG with a line per trajectory", "[eval][cli]") {
  const auto dir = tessera::test::scratchDir("eval_cli_plot");
  const auto traj = square(4, 40);
  writeTum(dir / "a.tum", traj);
  auto shifted = traj;  // 0.2 m off sideways from 8 s on
  for (auto& p : shifted)
    if (p.stamp_ns > 8'000'000'000) p.position.y() += 0.2;
  writeTum(dir / "b&c.tum", shifted);  // a name to escape in XML
  {
    std::ofstream rel(dir / "r.relations");
    for (int k = 0; k < 15; ++k) {
      // 1 s relations along the square, from the trajectory itself.
      const auto& p1 = traj[static_cast<std::size_t>(k) * 10];
      const auto& p2 = traj[static_cast<std::size_t>(k) * 10 + 10];
      const Pose2 d = between(p1.planar(), p2.planar());
      rel << k << " " << k + 1 << " " << d.x << " " << d.y << " 0 0 0 " << d.theta << "\n";
    }
  }
  const std::string rel = " --relations " + (dir / "r.relations").string();
  const std::string a = " --trajectory " + (dir / "a.tum").string();
  const std::string b = " --trajectory '" + (dir / "b&c.tum").string() + "'";
  const fs::path svg = dir / "plot.svg";
  auto read = [](const fs::path& path) {
    std::ifstream in(path);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
  };
  auto count = [](const std::string& text, const std::string& what) {
    std::size_t n = 0;
    for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
  };

  const CliRun single = runCli("eval relations" + a + rel + " --json", dir);
  REQUIRE(single.exit_code == 0);
  const CliRun two =
      runCli("eval relations" + a + b + rel + " --plot " + svg.string() + " --bins 5 --json", dir);
  INFO(two.err);
  REQUIRE(two.exit_code == 0);
  const auto j1 = nlohmann::json::parse(single.out);
  const auto j2 = nlohmann::json::parse(two.out);
  // The headline is the first trajectory's, as with one.
  for (const char* key : {"matched", "trans_mean_m", "trans_std_m", "rot_mean_deg"})
    CHECK(j2[key] == j1[key]);
  REQUIRE(j2["other_trajectories"].size() == 1);
  CHECK(j2["other_trajectories"][0]["trans_mean_m"].get<double>() > 0.01);
  CHECK(j2["plot"] == svg.string());

  const std::string text = read(svg);
  CHECK_THAT(text,
             Catch::StartsWith("<?xml") && Catch::Contains("<svg") && Catch::EndsWith("</svg>\n"));
  CHECK(count(text, "class=\"series\"") == 2);
  CHECK_THAT(text, Catch::Contains("a.tum: mean") && Catch::Contains("b&amp;c.tum: mean") &&
                       Catch::Contains("per 5 s bin"));
  CHECK(count(text, "&c.tum") == 0);
  // Written atomically: no temporary file is left beside it.
  std::size_t files = 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    files += name.ends_with(".svg") || name.find(".tmp") != std::string::npos;
  }
  CHECK(files == 1);

  // One trajectory, default 300 s bins: one line.
  const CliRun one = runCli("eval relations" + a + rel + " --plot " + svg.string(), dir);
  REQUIRE(one.exit_code == 0);
  CHECK(count(read(svg), "class=\"series\"") == 1);
  CHECK_THAT(read(svg), Catch::Contains("per 300 s bin"));

  // An output folder that does not exist: a usage error naming the file; nothing is computed.
  const CliRun missing = runCli("eval relations" + a + rel + " --plot /nonexistent/dir/x.svg", dir);
  CHECK(missing.exit_code == 2);
  CHECK_THAT(missing.err,
             Catch::Contains("/nonexistent/dir/x.svg") && Catch::Contains("does not exist"));
  const CliRun folder = runCli("eval relations" + a + rel + " --plot " + dir.string(), dir);
  CHECK(folder.exit_code == 2);
  CHECK_THAT(folder.err, Catch::Contains("is a folder"));
}

TEST_CASE("tessera eval: missing files are usage errors, bad lines name file:line", "[eval][cli]") {
  const auto dir = tessera::test::scratchDir("eval_cli_err");
  writeTum(dir / "good.tum", square(2, 10));
  {
    std::ofstream bad(dir / "bad.tum");
    bad << "# header\n0.0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0\n";
  }
  const std::string good = (dir / "good.tum").string();
  const CliRun missing =
      runCli("eval ate --estimate " + (dir / "nope.tum").string() + " --reference " + good, dir);
  CHECK(missing.exit_code == 2);
  CHECK_THAT(missing.err, Catch::Contains("nope.tum") && Catch::Contains("no such file"));

  const CliRun bad = runCli(
      "eval ate --estimate " + (dir / "bad.tum").string() + " --reference " + good + " --json",
      dir);
  CHECK(bad.exit_code == 1);
  CHECK_THAT(bad.err, Catch::Contains("bad.tum:3:"));
  CHECK(bad.out.empty());

  {
    std::ofstream rel(dir / "bad.relations");
    rel << "0 1 1 0 0 0 0 0\n0 1 1 0 zero 0 0 0\n";
  }
  const CliRun bad_rel = runCli(
      "eval relations --trajectory " + good + " --relations " + (dir / "bad.relations").string(),
      dir);
  CHECK(bad_rel.exit_code == 1);
  CHECK_THAT(bad_rel.err, Catch::Contains("bad.relations:2:") && Catch::Contains("(dz)"));

  const CliRun bad_delta =
      runCli("eval rpe --estimate " + good + " --reference " + good + " --delta -1", dir);
  CHECK(bad_delta.exit_code == 2);

  // Nothing to compare (other time base): an error, not a score of 0.
  auto late = square(2, 10);
  for (auto& p : late) p.stamp_ns += 5'000'000'000;
  writeTum(dir / "late.tum", late);
  const CliRun disjoint =
      runCli("eval ate --estimate " + (dir / "late.tum").string() + " --reference " + good, dir);
  CHECK(disjoint.exit_code == 1);
  CHECK_THAT(disjoint.err, Catch::Contains("no estimate/reference stamps"));
}

TEST_CASE("tessera eval loops counts a loop that disagrees with the reference as false",
          "[eval][cli]") {
  const auto dir = tessera::test::scratchDir("eval_loops_cli");
  // Keyframes every second along x; ground truth the same.
  std::vector<TumPose> keyframes;
  pose_graph::Graph3D g;
  for (int i = 0; i < 6; ++i) {
    const std::int64_t t = i * 1'000'000'000LL;
    const Pose3 p{Eigen::Vector3d(i * 0.5, 0, 0), Eigen::Quaterniond::Identity()};
    keyframes.push_back({t, p.t, p.q});
    g.ids.push_back(i);
    g.poses.push_back(p);
    g.fixed.push_back(i == 0);
  }
  auto edge = [&](int from, int to, double dx) {
    pose_graph::Edge3D e;
    e.from = from;
    e.to = to;
    e.measurement = Pose3{Eigen::Vector3d(dx, 0, 0), Eigen::Quaterniond::Identity()};
    g.edges.push_back(e);
  };
  for (int i = 0; i + 1 < 6; ++i) edge(i, i + 1, 0.5);  // odometry: never counted as loops
  edge(5, 0, -2.5);                                     // true: 0 is 2.5 m behind 5
  edge(4, 1, -1.0);                                     // false: 1 is 1.5 m behind 4
  pose_graph::writeG2o(g, dir / "graph.g2o");
  writeTum(dir / "keyframes.tum", keyframes);
  writeTum(dir / "ref.tum", keyframes);
  const std::string args = "eval loops --graph " + (dir / "graph.g2o").string() + " --keyframes " +
                           (dir / "keyframes.tum").string() + " --reference " +
                           (dir / "ref.tum").string();
  const CliRun run = runCli(args + " --json", dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  CHECK(j["loops"] == 2);
  CHECK(j["checked"] == 2);
  CHECK(j["false"] == 1);
  CHECK(j["precision"].get<double>() == Approx(0.5));

  // Keyframes that do not match the graph's nodes, and a missing graph, are clear errors.
  keyframes.pop_back();
  writeTum(dir / "short.tum", keyframes);
  const CliRun bad =
      runCli("eval loops --graph " + (dir / "graph.g2o").string() + " --keyframes " +
                 (dir / "short.tum").string() + " --reference " + (dir / "ref.tum").string(),
             dir);
  CHECK(bad.exit_code == 1);
  CHECK_THAT(bad.err, Catch::Contains("5 keyframes for a graph of 6 nodes"));
  const CliRun missing =
      runCli("eval loops --graph " + (dir / "none.g2o").string() + " --keyframes " +
                 (dir / "short.tum").string() + " --reference " + (dir / "ref.tum").string(),
             dir);
  CHECK(missing.exit_code == 2);
  CHECK_THAT(missing.err, Catch::Contains("none.g2o"));
}

TEST_CASE("tessera eval merged aligns several robots' trajectories once and scores each",
          "[eval][cli]") {
  const auto dir = tessera::test::scratchDir("eval_merged");
  // Two robots on squares in one world; their merged-frame trajectories share one frame
  // (rotated and shifted from the world), but robot 2's is placed 0.3 m off in it.
  const auto ref1 = square(4, 40);
  auto ref2 = ref1;
  for (auto& p : ref2) p = TumPose::fromPlanar(p.stamp_ns, Pose2(10, 2, 0.5) * p.planar());
  const Pose2 frame(3, -1, std::numbers::pi / 6);
  auto est1 = ref1, est2 = ref2;
  for (auto& p : est1) p = TumPose::fromPlanar(p.stamp_ns, frame * p.planar());
  for (auto& p : est2) p = TumPose::fromPlanar(p.stamp_ns, Pose2(0.3, 0, 0) * frame * p.planar());
  writeTum(dir / "ref1.tum", ref1);
  writeTum(dir / "ref2.tum", ref2);
  writeTum(dir / "est1.tum", est1);
  writeTum(dir / "est2.tum", est2);
  const auto at = [&](const char* f) { return (dir / f).string(); };
  const std::string files = " --estimate " + at("est1.tum") + " --reference " + at("ref1.tum") +
                            " --estimate " + at("est2.tum") + " --reference " + at("ref2.tum");
  const CliRun run = runCli("eval merged" + files + " --json", dir);
  INFO(run.err);
  REQUIRE(run.exit_code == 0);
  const auto j = nlohmann::json::parse(run.out);
  REQUIRE(j["trajectories"].size() == 2);
  for (const auto& t : j["trajectories"]) {
    CHECK(t["pairs"] == 160);
    CHECK(t["alone_rmse_m"].get<double>() < 1e-9);  // each alone is exact
  }
  // One alignment cannot put both right: about half the 0.3 m each.
  CHECK(j["trajectories"][0]["merged_rmse_m"].get<double>() > 0.1);
  CHECK(j["trajectories"][1]["merged_rmse_m"].get<double>() > 0.1);
  CHECK(j["trajectories"][1]["merged_rmse_m"].get<double>() < 0.3);

  // Bad use: counts differ, --map without --walls, a malformed file.
  const CliRun uneven = runCli("eval merged" + files + " --estimate " + at("est1.tum"), dir);
  CHECK(uneven.exit_code == 2);  // usage errors
  CHECK_THAT(uneven.err, Catch::Contains("3 --estimate but 2 --reference"));
  const CliRun map_only = runCli("eval merged" + files + " --map " + at("m.yaml"), dir);
  CHECK(map_only.exit_code == 2);
  CHECK_THAT(map_only.err, Catch::Contains("--map and --walls go together"));
  {
    std::ofstream bad(dir / "nan.tum");
    bad << "0.0 nan 0 0 0 0 0 1\n";
  }
  const CliRun nan =
      runCli("eval merged --estimate " + at("nan.tum") + " --reference " + at("ref1.tum"), dir);
  CHECK(nan.exit_code == 1);
  CHECK_THAT(nan.err, Catch::Contains("nan.tum:1"));
  { std::ofstream empty(dir / "empty.tum"); }
  const CliRun empty =
      runCli("eval merged --estimate " + at("empty.tum") + " --reference " + at("ref1.tum"), dir);
  CHECK(empty.exit_code == 1);
}
