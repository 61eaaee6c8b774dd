#include <tessera/laser_slam/graph_optimizer_actor.hpp>
#include <tessera/laser_slam/loop_detector_actor.hpp>
#include <tessera/laser_slam/map_assembler_actor.hpp>
#include <tessera/laser_slam/submap_graph.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/profile.hpp>

#include "../../shared_data.hpp"
#include "submap_messages.hpp"

#include <tessera/pose_graph/pose_graph_io.hpp>

#include <catch2/catch.hpp>

#include <algorithm>

#include <cmath>
#include <limits>
#include <numbers>

using namespace tessera;
using laser_slam::GraphOptimizerActor;
using laser_slam::GraphOptimizerActorOptions;
using laser_slam::SubmapConstraintInput;
using laser_slam::SubmapGraph;
using tessera::Pose2;
using Outcome = SubmapGraph::Outcome;

namespace {

// Submap origins on a 10 m square, one per corner and edge midpoint, heading along the route.
std::vector<Pose2> squareRoute() {
  // Drives 5 m per submap around a 10 m square, turning 90 degrees after every second one.
  std::vector<Pose2> p;
  Pose2 at;
  for (int i = 0; i < 8; ++i) {
    p.push_back(at);
    at = at * Pose2(5.0, 0.0, i % 2 == 1 ? std::numbers::pi / 2 : 0.0);
  }
  return p;
}

SubmapConstraintInput constraint(int from, int to, const Pose2& rel, bool revisit,
                                 double sigma = 0.05) {
  SubmapConstraintInput c;
  c.from = from;
  c.to = to;
  c.relative = rel;
  c.revisit = revisit;
  c.covariance = Eigen::Vector3d(sigma * sigma, sigma * sigma, 0.01 * sigma * sigma).asDiagonal();
  return c;
}

double distance(const Pose2& a, const Pose2& b) {
  return std::hypot(a.x - b.x, a.y - b.y);
}

}  // namespace

TEST_CASE("hand-overs place each new submap by composition without optimising",
          "[graph_optimizer]") {
  SubmapGraph g;
  g.addSubmap(0, Pose2());
  CHECK(g.addConstraint(constraint(0, 1, Pose2(5, 0, std::numbers::pi / 2), false)) ==
        Outcome::kAdded);
  CHECK(g.addConstraint(constraint(1, 2, Pose2(5, 0, 0), false)) == Outcome::kAdded);
  CHECK_FALSE(g.needsOptimization());
  CHECK(g.pose(2).x == Approx(5.0));
  CHECK(g.pose(2).y == Approx(5.0));
  CHECK(g.pose(2).theta == Approx(std::numbers::pi / 2));
}

TEST_CASE("a revisit closing a drifted loop pulls the submaps back to the truth",
          "[graph_optimizer]") {
  const auto truth = squareRoute();
  SubmapGraph g;
  g.addSubmap(0, truth[0]);
  // Hand-overs with a heading bias of 2 degrees each: the chain drifts by metres.
  for (std::size_t i = 0; i + 1 < truth.size(); ++i) {
    Pose2 rel = truth[i].inverse() * truth[i + 1];
    rel = rel * Pose2(0, 0, 2.0 * std::numbers::pi / 180);
    g.addConstraint(constraint(static_cast<int>(i), static_cast<int>(i + 1), rel, false));
  }
  const int last = static_cast<int>(truth.size()) - 1;
  const double drift = distance(g.pose(last), truth[last]);
  CHECK(drift > 1.0);
  // The loop detector sees submap 0 again from the last one, exactly and confidently.
  const auto c = constraint(last, 0, truth[last].inverse() * truth[0], true, 0.01);
  CHECK(g.addConstraint(c) == Outcome::kAdded);
  REQUIRE(g.needsOptimization());
  const auto s = g.optimize();
  CHECK(s.final_chi2 < s.initial_chi2);
  CHECK(distance(g.pose(last), truth[last]) < 0.25 * drift);
}

TEST_CASE("a second revisit between the same submaps is fused, an exact repeat ignored",
          "[graph_optimizer]") {
  SubmapGraph g;
  g.addSubmap(0, Pose2());
  g.addConstraint(constraint(0, 1, Pose2(5, 0, 0), false));
  g.addConstraint(constraint(1, 2, Pose2(5, 0, 0), false));
  CHECK(g.addConstraint(constraint(2, 0, Pose2(-9.8, 0, 0), true)) == Outcome::kAdded);
  CHECK(g.addConstraint(constraint(2, 0, Pose2(-9.8, 0, 0), true)) == Outcome::kDuplicate);
  // Seen from the other end, with the same uncertainty: fused into the same edge.
  CHECK(g.addConstraint(constraint(0, 2, Pose2(10.2, 0, 0), true)) == Outcome::kFused);
  CHECK(g.edges() == 3);
  const auto& fused = g.graph().edges.back();
  CHECK(fused.measurement.x() == Approx(-10.0).margin(1e-6));
}

TEST_CASE("a constraint's covariance is read in its from submap's frame, whatever its turn",
          "[graph_optimizer]") {
  // Submap 1 starts 10 m ahead of submap 0, turned 90 degrees. The hand-over is loose along
  // submap 0's x (1 m) and tight along its y (1 cm): moving submap 1 along 0's x costs little,
  // along 0's y a lot, though in submap 1's own frame those axes are swapped.
  SubmapGraph g;
  g.addSubmap(0, Pose2());
  auto c = constraint(0, 1, Pose2(10, 0, std::numbers::pi / 2), false);
  c.covariance = Eigen::Vector3d(1.0, 1e-4, 1e-4).asDiagonal();
  REQUIRE(g.addConstraint(c) == Outcome::kAdded);
  auto chi2Moved = [&](double dx, double dy) {
    pose_graph::Graph2D moved = g.graph();
    moved.poses[1] += Eigen::Vector3d(dx, dy, 0);
    return pose_graph::chi2(moved);
  };
  CHECK(chi2Moved(0.1, 0) == Approx(0.01));
  CHECK(chi2Moved(0, 0.1) == Approx(100.0));
}

TEST_CASE("scan matches of one pass fused into an edge saturate at their shared error",
          "[graph_optimizer]") {
  // 50 scan matches 2 -> 0 of 1 cm each: as independent they would give 1.4 mm; sharing a 5 cm
  // placement error they give about 5 cm. A camera revisit on the same pair is independent of
  // them and adds its information.
  laser_slam::SubmapGraphOptions o;  // the defaults: 0.05 m, 0.01 rad
  REQUIRE(o.closure_shared_std_linear == 0.05);
  laser_slam::SubmapGraphOptions off;
  off.closure_shared_std_linear = off.closure_shared_std_angular = 0;
  SubmapGraph shared(o), independent(off);
  for (SubmapGraph* g : {&shared, &independent}) {
    g->addSubmap(0, Pose2());
    g->addConstraint(constraint(0, 1, Pose2(5, 0, 0), false));
    g->addConstraint(constraint(1, 2, Pose2(5, 0, std::numbers::pi / 2), false));
    for (int k = 0; k < 50; ++k) {
      auto m = constraint(2, 0, Pose2(0.001 * k, 10, -std::numbers::pi / 2), true, 0.01);
      m.scan_match = true;
      g->addConstraint(m);
    }
    CHECK(g->edges() == 3);
  }
  auto closureStd = [](const SubmapGraph& g) {
    const auto& e = g.graph().edges.back();
    return std::sqrt(e.information.inverse()(0, 0));
  };
  CHECK(closureStd(independent) == Approx(0.01 / std::sqrt(50.0)).epsilon(0.01));
  CHECK(closureStd(shared) == Approx(std::sqrt(0.05 * 0.05 + 0.01 * 0.01 / 50)).epsilon(0.01));
  // The fused mean is the matches' mean, 0.0245 m along submap 2's x, which is -y of submap 0's
  // (the edge is kept 0 -> 2, lower id first).
  const auto& e = shared.graph().edges.back();
  REQUIRE(e.from == 0);
  CHECK(e.measurement.x() == Approx(10.0).epsilon(1e-9));
  CHECK(e.measurement.y() == Approx(-0.0245).epsilon(1e-6));
  const double before = shared.graph().edges.back().information(0, 0);
  auto camera = constraint(2, 0, Pose2(0.0123, 10, -std::numbers::pi / 2), true, 0.05);
  CHECK(shared.addConstraint(camera) == Outcome::kFused);
  CHECK(shared.graph().edges.back().information(0, 0) == Approx(before + 1 / 0.0025).epsilon(0.05));
  CHECK(shared.edges() == 3);
}

TEST_CASE("the shared closure error is refused when negative or half set", "[graph_optimizer]") {
  laser_slam::SubmapGraphOptions o;
  o.closure_shared_std_linear = -0.1;
  o.closure_shared_std_angular = 0.01;
  CHECK_THROWS_WITH(SubmapGraph(o), Catch::Contains("closure_shared_std_linear must be"));
  o.closure_shared_std_linear = 0.05;
  o.closure_shared_std_angular = 0;
  CHECK_THROWS_WITH(SubmapGraph(o), Catch::Contains("both 0 (off) or both > 0"));
  o.closure_shared_std_angular = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(SubmapGraph(o), Catch::Contains("closure_shared_std_angular must be finite"));
}

TEST_CASE("constraints arriving before their submaps wait and are resolved in any order",
          "[graph_optimizer]") {
  SubmapGraph g;
  // Hand-overs arrive backwards, then a revisit, and only then the first submap.
  CHECK(g.addConstraint(constraint(2, 3, Pose2(1, 0, 0), false)) == Outcome::kPending);
  CHECK(g.addConstraint(constraint(1, 2, Pose2(1, 0, 0), false)) == Outcome::kPending);
  CHECK(g.addConstraint(constraint(3, 0, Pose2(-3, 0, 0), true)) == Outcome::kPending);
  CHECK(g.addConstraint(constraint(0, 1, Pose2(1, 0, 0), false)) == Outcome::kPending);
  CHECK(g.pending() == 4);
  g.addSubmap(0, Pose2(10, 10, 0));
  CHECK(g.pending() == 0);
  CHECK(g.nodes() == 4);
  CHECK(g.edges() == 4);
  CHECK(g.pose(3).x == Approx(13.0));
}

TEST_CASE("invalid constraints are rejected with the reason and the pending queue is bounded",
          "[graph_optimizer]") {
  laser_slam::SubmapGraphOptions o;
  o.max_pending = 2;
  SubmapGraph g(o);
  g.addSubmap(0, Pose2());
  CHECK(g.addConstraint(constraint(0, 0, Pose2(), true)) == Outcome::kRejected);
  CHECK_THAT(g.lastError(), Catch::Contains("links a submap to itself"));
  auto singular = constraint(0, 1, Pose2(1, 0, 0), false);
  singular.covariance.setZero();
  CHECK(g.addConstraint(singular) == Outcome::kRejected);
  CHECK_THAT(g.lastError(), Catch::Contains("not positive definite"));
  auto nan = constraint(0, 1, Pose2(1, 0, 0), false);
  nan.relative.x = std::numeric_limits<double>::quiet_NaN();
  CHECK(g.addConstraint(nan) == Outcome::kRejected);
  CHECK_THAT(g.lastError(), Catch::Contains("non-finite"));
  CHECK(g.addConstraint(constraint(7, 8, Pose2(), false)) == Outcome::kPending);
  CHECK(g.addConstraint(constraint(8, 9, Pose2(), false)) == Outcome::kPending);
  CHECK(g.addConstraint(constraint(9, 10, Pose2(), false)) == Outcome::kPending);
  CHECK(g.pending() == 2);
  CHECK_THAT(g.lastError(), Catch::Contains("dropped the oldest, 7 -> 8"));
  CHECK(g.nodes() == 1);
}

namespace {

void pushSubmap(ActorHarness& h, int id, const Pose2& guess) {
  h.push<msg::Submap>("submaps", [&](auto& b) { test::fillSubmap(b, id, guess, 1000 + id); });
}

void pushConstraint(ActorHarness& h, const SubmapConstraintInput& c, bool with_covariance = true) {
  h.push<msg::SubmapConstraint>("constraints", [&](auto& b) {
    setHeader(b.initHeader(), 2000, "map", 0);
    b.setFromId(static_cast<std::uint32_t>(c.from));
    b.setToId(static_cast<std::uint32_t>(c.to));
    writePose(b.initRelative(), tessera::Pose2{c.relative.x, c.relative.y, c.relative.theta},
              with_covariance ? &c.covariance : nullptr);
    b.setKind(c.revisit ? msg::SubmapConstraint::Kind::REVISIT
                        : msg::SubmapConstraint::Kind::HAND_OVER);
  });
}

std::int64_t count(const Summary& s, const std::string& key) {
  return std::get<std::int64_t>(s.at(key));
}

}  // namespace

TEST_CASE("graph_optimizer actor publishes optimised submap poses from out-of-order input",
          "[graph_optimizer]") {
  ActorHarness h(std::make_unique<GraphOptimizerActor>(GraphOptimizerActorOptions{}));
  const auto truth = squareRoute();
  // A revisit first (both ends unknown), then the submaps and their biased hand-overs.
  const int last = static_cast<int>(truth.size()) - 1;
  pushConstraint(h, constraint(last, 0, truth[last].inverse() * truth[0], true, 0.01));
  // Submap 0 anchors the map frame; the others' carried guesses are wrong and must not matter.
  for (int i = 0; i <= last; ++i) pushSubmap(h, i, i == 0 ? truth[0] : truth[i] * Pose2(1, 1, 0));
  for (int i = 0; i < last; ++i) {
    Pose2 rel = (truth[i].inverse() * truth[i + 1]) * Pose2(0, 0, 2.0 * std::numbers::pi / 180);
    pushConstraint(h, constraint(i, i + 1, rel, false));
  }
  pushConstraint(h, constraint(0, 1, truth[0].inverse() * truth[1], false), false);  // no cov
  pushConstraint(h, constraint(3, 42, Pose2(), true));  // submap 42 never comes
  h.runUntilIdle();
  h.stop();

  const auto published = h.published<msg::SubmapPoses>("submap_poses");
  REQUIRE(!published.empty());
  const auto final_poses = published.back()->getPoses();
  REQUIRE(final_poses.size() == truth.size());
  const auto p = final_poses[last].getPose();
  CHECK(std::hypot(p.getX() - truth[last].x, p.getY() - truth[last].y) < 0.5);
  Summary s;
  h.actor().summarize(s);
  CHECK(count(s, "graph_nodes") == static_cast<std::int64_t>(truth.size()));
  CHECK(count(s, "graph_edges") == static_cast<std::int64_t>(truth.size()));
  CHECK(count(s, "constraints_rejected") == 1);
  CHECK(count(s, "constraints_unresolved") == 1);
  CHECK(count(s, "optimizations") >= 1);
}

TEST_CASE("graph_optimizer writes the final graph as g2o that reads back to the published poses",
          "[graph_optimizer]") {
  const auto dir = test::scratchDir("graph_g2o");
  ActorHarness h(std::make_unique<GraphOptimizerActor>(GraphOptimizerActorOptions{}), dir.string());
  const auto truth = squareRoute();
  const int last = static_cast<int>(truth.size()) - 1;
  for (int i = 0; i <= last; ++i) pushSubmap(h, i, truth[i]);
  for (int i = 0; i < last; ++i) {
    const Pose2 rel = (truth[i].inverse() * truth[i + 1]) * Pose2(0.1, 0, 0.02);
    pushConstraint(h, constraint(i, i + 1, rel, false));
  }
  pushConstraint(h, constraint(last, 0, truth[last].inverse() * truth[0], true, 0.01));
  h.runUntilIdle();
  h.stop();

  const auto graph = pose_graph::readPoseGraph2D(dir / "graph.g2o");
  REQUIRE(graph.size() == static_cast<int>(truth.size()));
  REQUIRE(graph.edges.size() == truth.size());
  CHECK(graph.fixed[graph.index(0)]);
  CHECK(std::count(graph.fixed.begin(), graph.fixed.end(), true) == 1);
  const auto published = h.published<msg::SubmapPoses>("submap_poses");
  REQUIRE(!published.empty());
  for (const auto& p : published.back()->getPoses()) {
    const Eigen::Vector3d v = graph.poses[graph.index(p.getId())];
    CHECK(v.x() == Approx(p.getPose().getX()).margin(1e-12));
    CHECK(v.y() == Approx(p.getPose().getY()).margin(1e-12));
  }
  // The loop closure, with its information (inverse covariance, 0.01 m sigma).
  const auto& closure = graph.edges.back();
  CHECK(closure.from == last);
  CHECK(closure.to == 0);
  CHECK(closure.information(0, 0) == Approx(1.0 / (0.01 * 0.01)));
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::string>(s.at("graph_path")) == (dir / "graph.g2o").string());
  std::filesystem::remove_all(dir);
}

TEST_CASE("graph_optimizer reports an unwritable graph file in its summary without throwing",
          "[graph_optimizer]") {
  GraphOptimizerActorOptions o;
  o.g2o_file = "no_such_dir/graph.g2o";
  const auto dir = test::scratchDir("graph_g2o_bad");
  ActorHarness h(std::make_unique<GraphOptimizerActor>(o), dir.string());
  pushSubmap(h, 0, Pose2());
  pushSubmap(h, 1, Pose2(1, 0, 0));
  pushConstraint(h, constraint(0, 1, Pose2(1, 0, 0), false));
  h.runUntilIdle();
  REQUIRE_NOTHROW(h.stop());
  Summary s;
  h.actor().summarize(s);
  REQUIRE(s.count("graph_write_error") == 1);
  CHECK(std::get<std::string>(s.at("graph_write_error")).find("no_such_dir") != std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST_CASE("graph_optimizer refuses bad options", "[graph_optimizer]") {
  GraphOptimizerActorOptions o;
  o.graph.optimizer.sgd.iterations = -1;
  CHECK_THROWS_WITH(GraphOptimizerActor(o),
                    Catch::Contains("graph.optimizer.sgd.iterations must be >= 0"));
  o = {};
  o.graph.optimizer.ceres.max_iterations = 0;
  CHECK_THROWS_WITH(GraphOptimizerActor(o),
                    Catch::Contains("graph.optimizer.ceres.max_iterations must be >= 1"));
  o = {};
  o.graph.optimizer.ceres.huber_delta = -1;
  CHECK_THROWS_AS(GraphOptimizerActor(o), ConfigError);
  o = {};
  o.frame_id = "";
  CHECK_THROWS_AS(GraphOptimizerActor(o), ConfigError);
}

namespace {
GraphOptimizerActorOptions loadGraphOptimizer(const std::string& params,
                                              const std::vector<std::string>& sets = {}) {
  const Profile p = parseProfile(
      "actors:\n  optimizer:\n    type: graph_optimizer\n    params:\n" + params, "p.yaml", sets);
  return loadOptions<GraphOptimizerActorOptions>(p.actors.at(0).params);
}
}  // namespace

TEST_CASE("graph_optimizer reads its nested graph and scan_graph groups", "[graph_optimizer]") {
  // Defaults: what the shipped profiles got before the groups (100 warm-started iterations).
  const auto d = loadGraphOptimizer("      {}\n");
  CHECK(d.graph.optimizer.solver == pose_graph::Solver::kSgdCeres);
  CHECK(d.graph.optimizer.ceres.max_iterations == 100);
  CHECK(d.graph.optimizer.ceres.huber_delta == 1.0);
  CHECK_FALSE(d.scan_graph.enabled);
  CHECK(d.scan_graph.options.optimizer.solver == pose_graph::Solver::kCeres);
  CHECK(d.scan_graph.options.optimizer.ceres.max_iterations == 50);

  const auto o = loadGraphOptimizer(
      "      graph:\n        optimizer: {solver: ceres, ceres: {max_iterations: 30, method: gn}}\n"
      "      scan_graph: {enabled: true, node_every: 3}\n",
      {"optimizer.scan_graph.optimizer.ceres.huber_delta=0.5"});
  CHECK(o.graph.optimizer.solver == pose_graph::Solver::kCeres);
  CHECK(o.graph.optimizer.ceres.max_iterations == 30);
  CHECK(o.graph.optimizer.ceres.method == pose_graph::CeresOptions::Method::kGaussNewton);
  CHECK(o.scan_graph.enabled);
  CHECK(o.scan_graph.options.node_every == 3);
  CHECK(o.scan_graph.options.optimizer.ceres.huber_delta == 0.5);
  CHECK_THROWS_WITH(loadGraphOptimizer("      graph: {optimizer: {solver: newton}}\n"),
                    Catch::Contains("expected one of sgd | ceres | sgd+ceres, got 'newton'"));
}

TEST_CASE("graph_optimizer's old flat keys fail naming the new ones", "[graph_optimizer]") {
  CHECK_THROWS_WITH(loadGraphOptimizer("      ceres_iterations: 100\n"),
                    Catch::Contains("actors.optimizer.params.ceres_iterations, line 5: moved to "
                                    "graph.optimizer.ceres.max_iterations"));
  CHECK_THROWS_WITH(loadGraphOptimizer("      scan_sigma_linear: 0.5\n"),
                    Catch::Contains("moved to scan_graph.intra_sigma_linear"));
  // The old bool, now the name of a group.
  CHECK_THROWS_WITH(loadGraphOptimizer("      scan_graph: true\n"),
                    Catch::Contains("actors.optimizer.params.scan_graph, line 5: moved to "
                                    "scan_graph.enabled"));
  CHECK_THROWS_WITH(loadGraphOptimizer("      {}\n", {"optimizer.scan_graph=true"}),
                    Catch::Contains("moved to optimizer.scan_graph.enabled"));
  CHECK_THROWS_WITH(loadGraphOptimizer("      {}\n", {"optimizer.solver=ceres"}),
                    Catch::Contains("moved to optimizer.graph.optimizer.solver"));
}

TEST_CASE("map_assembler draws submaps at the optimised poses when asked to", "[graph_optimizer]") {
  laser_slam::MapAssemblerOptions o;
  o.optimized_poses = true;
  ActorHarness h(std::make_unique<laser_slam::MapAssemblerActor>(o));
  pushSubmap(h, 0, Pose2());
  pushSubmap(h, 1, Pose2(3, 0, 0));
  pushConstraint(h, constraint(0, 1, Pose2(2, 0, 0), false));
  h.runUntilIdle();
  auto& actor = static_cast<laser_slam::MapAssemblerActor&>(h.actor());
  CHECK(actor.assembler().pose(1).x == Approx(2.0));  // chained
  h.push<msg::SubmapPoses>("submap_poses", [](auto& b) {
    auto poses = b.initPoses(2);
    poses[0].setId(0);
    writePose(poses[0].initPose(), tessera::Pose2{0, 0, 0});
    poses[1].setId(1);
    writePose(poses[1].initPose(), tessera::Pose2{2.5, 0.5, 0.1});
  });
  h.runUntilIdle();
  CHECK(actor.assembler().pose(1).x == Approx(2.5));
  CHECK(actor.assembler().pose(1).y == Approx(0.5));
  h.stop();
}

TEST_CASE("trajectory poses move with their optimised submap", "[graph_optimizer]") {
  GraphOptimizerActorOptions o;
  o.compose_trajectory = true;
  ActorHarness h(std::make_unique<GraphOptimizerActor>(o));
  // Submap 0 holds scans up to t = 1000 ns, submap 1 the rest; chained origins as the builder
  // saw them. A confident revisit then says submap 1 starts 0.5 m further along y.
  pushSubmap(h, 0, Pose2());  // stamped 1000 by pushSubmap
  pushConstraint(h, constraint(0, 1, Pose2(4, 0, 0), false));
  pushSubmap(h, 1, Pose2(4, 0, 0));  // stamped 1001
  for (int k = 0; k < 4; ++k) {
    h.push<msg::PoseStamped>("trajectory", [&](auto& b) {
      setHeader(b.initHeader(), k < 2 ? 500 + k : 1001 + k, "map", 0);
      writePose(b.initPose(), tessera::Pose2{k * 2.0, 0.0, 0.0});
    });
  }
  pushConstraint(h, constraint(0, 1, Pose2(4, 0.5, 0), true, 0.001));
  h.runUntilIdle();
  h.stop();
  const auto out = h.published<msg::PoseStamped>("trajectory_final");
  REQUIRE(out.size() == 4);
  // Poses in submap 0 stay; poses in submap 1 follow it (fused hand-over + revisit: y between
  // 0 and 0.5, dominated by the confident revisit).
  CHECK(out[0]->getPose().getY() == Approx(0.0).margin(1e-9));
  CHECK(out[1]->getPose().getY() == Approx(0.0).margin(1e-9));
  CHECK(out[2]->getPose().getY() > 0.45);
  CHECK(out[3]->getPose().getY() == Approx(out[2]->getPose().getY()));
  CHECK(out[3]->getPose().getX() - out[2]->getPose().getX() == Approx(2.0));
}

TEST_CASE("loop_detector refuses bad options and skips a malformed submap", "[loop_detector]") {
  laser_slam::LoopDetectorOptions o;
  o.every_n_scans = 0;
  CHECK_THROWS_AS(laser_slam::LoopDetectorActor(o), ConfigError);
  o = {};
  o.window_linear = 5;
  o.window_linear_max = 1;
  CHECK_THROWS_AS(laser_slam::LoopDetectorActor(o), ConfigError);
  o = {};
  o.matcher.min_score = 2;
  CHECK_THROWS_AS(laser_slam::LoopDetectorActor(o), ConfigError);

  ActorHarness h(
      std::make_unique<laser_slam::LoopDetectorActor>(laser_slam::LoopDetectorOptions{}));
  h.push<msg::Submap>("submaps", [](auto& b) {
    b.setId(0);
    auto g = b.initGrid();
    g.setResolution(0.05f);
    g.setWidth(4);
    g.setHeight(4);
    g.initCells(3);  // not 4 x 4
    b.setFinished(true);
  });
  h.runUntilIdle();
  h.stop();
  Summary s;
  h.actor().summarize(s);
  CHECK(count(s, "loop_submaps_rejected") == 1);
  CHECK(count(s, "loops_published") == 0);
}

namespace lifelong_test {

/// Submap `id` with a 4 x 4 m grid, every cell known (free): submaps at the same place cover
/// each other.
void pushRoomSubmap(ActorHarness& h, int id, const Pose2& origin) {
  h.push<msg::Submap>("submaps", [&](auto& b) {
    setHeader(b.initHeader(), 1000 + id, "map", 0);
    b.setId(static_cast<std::uint32_t>(id));
    auto g = b.initGrid();
    g.setResolution(0.1f);
    g.setWidth(40);
    g.setHeight(40);
    writePose(g.initOrigin(), tessera::Pose2{0, 0, 0});
    auto cells = mutableViewInt8(g.initCells(1600));
    std::fill(cells.begin(), cells.end(), std::int8_t{0});
    for (int k = 0; k < 40; ++k) cells[static_cast<std::size_t>(k)] = 100;  // a wall
    writePose(b.initGlobalPose(), tessera::Pose2{origin.x, origin.y, origin.theta});
    b.setFinished(true);
  });
}

void pushTrimmed(ActorHarness& h, const std::vector<std::pair<int, Pose2>>& poses,
                 const std::vector<std::uint32_t>& trimmed) {
  h.push<msg::SubmapPoses>("submap_poses", [&](auto& b) {
    auto list = b.initPoses(static_cast<unsigned>(poses.size()));
    for (unsigned i = 0; i < poses.size(); ++i) {
      list[i].setId(static_cast<std::uint32_t>(poses[i].first));
      writePose(list[i].initPose(), poses[i].second);
    }
    auto t = b.initTrimmed(static_cast<unsigned>(trimmed.size()));
    for (unsigned i = 0; i < trimmed.size(); ++i) t.set(i, trimmed[i]);
  });
}

}  // namespace lifelong_test

TEST_CASE("graph_optimizer in lifelong mode trims submaps newer ones cover and lists them",
          "[graph_optimizer][lifelong]") {
  GraphOptimizerActorOptions o;
  o.lifelong.enabled = true;
  o.lifelong.trimmer.keep_newest = 1;
  ActorHarness h(std::make_unique<GraphOptimizerActor>(o));
  // Five laps over the same room: each submap starts where the previous one did.
  for (int id = 0; id < 5; ++id) {
    if (id > 0) pushConstraint(h, constraint(id - 1, id, Pose2(0.02, 0, 0), false));
    lifelong_test::pushRoomSubmap(h, id, Pose2(0.02 * id, 0, 0));
    h.runUntilIdle();
  }
  // A late loop closure naming a trimmed submap is refused, not kept waiting.
  pushConstraint(h, constraint(4, 2, Pose2(-0.04, 0, 0), true));
  h.runUntilIdle();
  h.stop();
  const auto published = h.published<msg::SubmapPoses>("submap_poses");
  REQUIRE(!published.empty());
  const auto last = published.back();
  // The anchor (0) and the newest (4) stay; 1, 2 and 3 were each covered by a newer one.
  REQUIRE(last->getTrimmed().size() == 3);
  CHECK(last->getTrimmed()[0] == 1);
  CHECK(last->getTrimmed()[2] == 3);
  REQUIRE(last->getPoses().size() == 2);
  CHECK(last->getPoses()[1].getId() == 4);
  CHECK(last->getPoses()[1].getPose().getX() == Approx(0.08).margin(1e-6));
  Summary s;
  h.actor().summarize(s);
  CHECK(count(s, "graph_nodes") == 2);
  CHECK(count(s, "submaps_trimmed") == 3);
  CHECK(count(s, "constraints_rejected") == 1);
  CHECK(count(s, "constraints_unresolved") == 0);
  CHECK(count(s, "trimmer_submaps") == 2);
}

TEST_CASE("graph_optimizer refuses lifelong mode with what keeps every scan",
          "[graph_optimizer][lifelong]") {
  GraphOptimizerActorOptions o;
  o.lifelong.enabled = true;
  o.scan_graph.enabled = true;
  CHECK_THROWS_WITH(GraphOptimizerActor(o), Catch::Contains("scan_graph.enabled"));
  o.scan_graph.enabled = false;
  o.compose_trajectory = true;
  CHECK_THROWS_WITH(GraphOptimizerActor(o), Catch::Contains("compose_trajectory"));
  o.compose_trajectory = false;
  o.lifelong.trimmer.min_own_fraction = -1;
  CHECK_THROWS_WITH(GraphOptimizerActor(o), Catch::Contains("lifelong.min_own_fraction"));
}

TEST_CASE("loop_detector and map_assembler drop the submaps lifelong mapping trimmed",
          "[loop_detector][lifelong]") {
  laser_slam::LoopDetectorOptions lo;
  lo.optimized_poses = true;
  ActorHarness loops(std::make_unique<laser_slam::LoopDetectorActor>(lo));
  laser_slam::MapAssemblerOptions ao;
  ao.optimized_poses = true;
  ActorHarness assembler(std::make_unique<laser_slam::MapAssemblerActor>(ao));
  for (int id = 0; id < 3; ++id) {
    lifelong_test::pushRoomSubmap(loops, id, Pose2(0.02 * id, 0, 0));
    lifelong_test::pushRoomSubmap(assembler, id, Pose2(0.02 * id, 0, 0));
    if (id > 0) pushConstraint(assembler, constraint(id - 1, id, Pose2(0.02, 0, 0), true));
  }
  loops.runUntilIdle();
  assembler.runUntilIdle();
  auto& a = static_cast<laser_slam::MapAssemblerActor&>(assembler.actor());
  CHECK(a.assembler().size() == 3);
  const std::vector<std::pair<int, Pose2>> kept = {{0, Pose2()}, {2, Pose2(0.04, 0, 0)}};
  lifelong_test::pushTrimmed(loops, kept, {1});
  lifelong_test::pushTrimmed(assembler, kept, {1});
  loops.runUntilIdle();
  assembler.runUntilIdle();
  CHECK(a.assembler().size() == 2);
  // A late message about the trimmed submap is ignored, not drawn again.
  lifelong_test::pushRoomSubmap(assembler, 1, Pose2(0.02, 0, 0));
  pushConstraint(assembler, constraint(1, 2, Pose2(0.02, 0, 0), true));
  assembler.runUntilIdle();
  CHECK(a.assembler().size() == 2);
  loops.stop();
  assembler.stop();
  Summary ls, as;
  loops.actor().summarize(ls);
  assembler.actor().summarize(as);
  CHECK(count(ls, "submaps_searched") == 2);
  CHECK(count(ls, "submaps_trimmed") == 1);
  CHECK(count(as, "submaps_trimmed") == 1);
  CHECK(count(as, "submaps_held") == 2);
  CHECK(count(as, "ignored_trimmed") == 2);
  // The saved state holds no constraint naming the trimmed submap.
  CHECK(count(as, "constraints_received") == 3);
}

TEST_CASE(
    "loop_detector searches a just-finished submap where the graph last put it, not at its "
    "chained pose",
    "[loop_detector]") {
  // The bug: between a submap's end and the next graph update, the finished submap was searched
  // at its chained origin, which after laps of odometry drift is metres from the optimised one,
  // so the robot's own estimate (chained from that submap) was off by as much and a look-alike
  // place within the window could be accepted as a closure.
  laser_slam::LoopDetectorOptions o;
  o.optimized_poses = true;
  o.publish_at_match = true;
  ActorHarness h(std::make_unique<laser_slam::LoopDetectorActor>(o));
  lifelong_test::pushRoomSubmap(h, 0, Pose2());
  pushConstraint(h, constraint(0, 1, Pose2(5, 0, 0), false));  // submap 1 chained at (5, 0)
  h.runUntilIdle();
  // The graph moved submap 1 (still being built) to (5, 2).
  lifelong_test::pushTrimmed(h, {{0, Pose2()}, {1, Pose2(5, 2, 0.1)}}, {});
  h.runUntilIdle();
  lifelong_test::pushRoomSubmap(h, 1, Pose2(5, 0, 0));  // finished, carrying its chained pose
  h.runUntilIdle();
  auto& actor = static_cast<laser_slam::LoopDetectorActor&>(h.actor());
  REQUIRE(actor.searchOrigin(1).has_value());
  CHECK(actor.searchOrigin(1)->y == Approx(2.0));
  CHECK(actor.searchOrigin(1)->theta == Approx(0.1));
  // A submap the graph never placed follows the newest finished one: chained from it.
  pushConstraint(h, constraint(1, 2, Pose2(5, 0, 0), false));
  lifelong_test::pushRoomSubmap(h, 2, Pose2(10, 0, 0));
  h.runUntilIdle();
  REQUIRE(actor.searchOrigin(2).has_value());
  const Pose2 expected = Pose2(5, 2, 0.1) * Pose2(5, 0, 0);
  CHECK(actor.searchOrigin(2)->x == Approx(expected.x));
  CHECK(actor.searchOrigin(2)->y == Approx(expected.y));
  CHECK(!actor.searchOrigin(7).has_value());
  h.stop();
}

TEST_CASE("graph_optimizer in lifelong mode keeps a submap whose grid it cannot read",
          "[graph_optimizer][lifelong]") {
  GraphOptimizerActorOptions o;
  o.lifelong.enabled = true;
  o.lifelong.trimmer.keep_newest = 1;
  ActorHarness h(std::make_unique<GraphOptimizerActor>(o));
  lifelong_test::pushRoomSubmap(h, 0, Pose2());
  pushConstraint(h, constraint(0, 1, Pose2(0.02, 0, 0), false));
  // Submap 1: a truncated grid (3 cells for 2 x 2), then one with a NaN resolution.
  h.push<msg::Submap>("submaps", [](auto& b) {
    test::fillSubmap(b, 1, Pose2(0.02, 0, 0), 1001);
    b.getGrid().initCells(3);
  });
  pushConstraint(h, constraint(1, 2, Pose2(0.02, 0, 0), false));
  h.push<msg::Submap>("submaps", [](auto& b) {
    test::fillSubmap(b, 2, Pose2(0.04, 0, 0), 1002);
    b.getGrid().setResolution(std::numeric_limits<float>::quiet_NaN());
  });
  for (int id = 3; id < 5; ++id) {
    pushConstraint(h, constraint(id - 1, id, Pose2(0.02, 0, 0), false));
    lifelong_test::pushRoomSubmap(h, id, Pose2(0.02 * id, 0, 0));
  }
  h.runUntilIdle();
  h.stop();
  Summary s;
  h.actor().summarize(s);
  // 1 and 2 have no footprint: never trimmed; 3 is covered by 4.
  CHECK(count(s, "submaps_trimmed") == 1);
  CHECK(count(s, "graph_nodes") == 4);
  CHECK(count(s, "trimmer_submaps") == 2);
}
