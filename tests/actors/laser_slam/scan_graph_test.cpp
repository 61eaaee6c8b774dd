// ScanGraph (scan-level pose graph) and the graph_optimizer actor's scan_graph mode: a closure
// on one scan moves that scan and its submap, shared scans are one node, non-node scans are
// interpolated, bad input is refused with the reason.
#include <tessera/laser_slam/graph_optimizer_actor.hpp>
#include <tessera/laser_slam/scan_graph.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>

#include "submap_messages.hpp"

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

using namespace tessera;
using laser_slam::ScanGraph;
using laser_slam::ScanGraphOptions;
using laser_slam::ScanLoopInput;
using laser_slam::StampedPose2;
using laser_slam::SubmapConstraintInput;
using tessera::Pose2;

namespace {

constexpr std::int64_t kSecond = 1'000'000'000;

// Submap 0 holds the scans at t = 0..4 s, 1 m apart along x; submap 1 starts at the scan that
// ended submap 0 (t = 4 s, 4 m) and holds t = 4..8 s. Consistent hand-over 0 -> 1.
std::vector<StampedPose2> straight(int first_second) {
  std::vector<StampedPose2> t;
  for (int i = 0; i <= 4; ++i) t.push_back({(first_second + i) * kSecond, Pose2(i, 0, 0)});
  return t;
}

Eigen::Matrix3d covariance(double sigma_linear, double sigma_angular) {
  return Eigen::Vector3d(sigma_linear * sigma_linear, sigma_linear * sigma_linear,
                         sigma_angular * sigma_angular)
      .asDiagonal();
}

SubmapConstraintInput handOver() {
  SubmapConstraintInput c;
  c.from = 0;
  c.to = 1;
  c.relative = Pose2(4, 0, 0);
  c.covariance = covariance(0.05, 0.01);
  return c;
}

// The robot at t = 8 s seen from submap 0 0.4 m further left than the chain has it, with the
// same closure as a submap -> submap revisit (current submap 1 -> matched submap 0).
std::pair<ScanLoopInput, SubmapConstraintInput> closure(std::int64_t stamp = 8 * kSecond) {
  ScanLoopInput l;
  l.matched = 0;
  l.stamp_ns = stamp;
  l.pose = Pose2(8, 0.4, 0);
  l.covariance = covariance(0.02, 0.01);
  SubmapConstraintInput f;
  f.from = 1;
  f.to = 0;
  f.relative = Pose2(4, 0, 0) * l.pose.inverse();
  f.covariance = covariance(0.02, 0.01);
  f.revisit = true;
  return {l, f};
}

// Plain least squares: the closures below disagree with the chain by many sigmas on purpose,
// which the default Huber loss would (rightly) discount. Tight intra-submap edges and the
// hand-over kept: the submaps carry their scans, so what a closure moves is easy to tell.
ScanGraphOptions plain() {
  ScanGraphOptions o;
  o.optimizer.ceres.huber_delta = 0;
  o.intra_sigma_linear = 0.05;
  o.intra_sigma_angular = 0.01;
  o.shared_handovers = true;
  return o;
}

ScanGraph twoSubmaps(const ScanGraphOptions& o = plain()) {
  ScanGraph g(o);
  REQUIRE(g.addSubmap(0, straight(0)));
  REQUIRE(g.addSubmap(1, straight(4)));
  REQUIRE(g.addConstraint(handOver()));
  return g;
}

const std::map<int, Pose2> kStart{{0, Pose2()}, {1, Pose2(4, 0, 0)}};

Pose2 scanAt(const ScanGraph& g, int second) {
  Pose2 p;
  REQUIRE(g.scanPose(second * kSecond, p));
  return p;
}

}  // namespace

TEST_CASE("scan graph: a consistent graph stays where its submaps and smoothed poses put it",
          "[scan_graph]") {
  ScanGraph g = twoSubmaps();
  g.optimize(kStart);
  // The scan at t = 4 s ends submap 0 and starts submap 1: one node with an edge from each.
  CHECK(g.scanNodes() == 9);
  CHECK(g.nodes() == 11);
  for (int s = 0; s <= 8; ++s) {
    const Pose2 p = scanAt(g, s);
    CHECK(p.x == Approx(s).margin(1e-6));
    CHECK(p.y == Approx(0).margin(1e-6));
  }
  CHECK(g.submapPoses().at(1).x == Approx(4).margin(1e-6));
  Pose2 none;
  CHECK_FALSE(g.scanPose(100 * kSecond, none));
}

TEST_CASE("scan graph: a submap started lost does not share its first scan with the one before",
          "[scan_graph]") {
  // The robot was carried 50 m to the left unseen at t = 4 s: the builder, lost, started submap 1
  // where the odometry says (the lost hand-over, wide), and a camera revisit later placed it.
  auto build = [](bool lost) {
    ScanGraph g(plain());
    REQUIRE(g.addSubmap(0, straight(0)));
    REQUIRE(g.addSubmap(1, straight(4)));
    SubmapConstraintInput h = handOver();
    h.lost = lost;
    h.covariance = covariance(10.0, 1.0);
    REQUIRE(g.addConstraint(h));
    SubmapConstraintInput r;  // pose of submap 0's origin in submap 1: submap 1 is at (4, 50)
    r.from = 1;
    r.to = 0;
    r.relative = Pose2(4, 50, 0).inverse();
    r.covariance = covariance(0.05, 0.01);
    r.revisit = true;
    REQUIRE(g.addConstraint(r));
    g.optimize({{0, Pose2()}, {1, Pose2(4, 0, 0)}});
    return g;
  };
  const ScanGraph lost = build(true);
  CHECK(lost.scanNodes() == 10);  // t = 4 s twice: the end of submap 0 and the start of 1
  CHECK(lost.submapPoses().at(1).y == Approx(50).margin(0.05));
  CHECK(scanAt(lost, 8).y == Approx(50).margin(0.05));
  // Submap 0's scans stay where it is; the shared stamp answers for the submap that ended there.
  CHECK(scanAt(lost, 4).y == Approx(0).margin(0.05));
  // A hand-over that was not lost joins the two at the shared scan, against the revisit.
  const ScanGraph joined = build(false);
  CHECK(joined.scanNodes() == 9);
  CHECK(joined.submapPoses().at(1).y < 40);
}

TEST_CASE("scan graph: a closure on one scan pulls the scan and its submap toward the match",
          "[scan_graph]") {
  ScanGraph g = twoSubmaps();
  const auto [loop, fallback] = closure();
  REQUIRE(g.addLoop(loop, fallback));
  g.optimize(kStart);
  CHECK(g.loopsOnScans() == 1);
  CHECK(g.loopsOnSubmaps() == 0);
  const Pose2 closed = scanAt(g, 8);
  // Mostly where the confident match says, not rigidly where its submap carries it.
  CHECK(closed.y > 0.2);
  CHECK(closed.y < 0.4);
  const Pose2 submap1 = g.submapPoses().at(1);
  const Pose2 in_own = submap1.inverse() * closed;
  // The scan sits between its own submap and the one it closed against: its pose in submap 1
  // is no longer exactly the smoothed one, and submap 1 itself moved (turned left) too.
  CHECK(std::abs(in_own.y) > 0.01);
  CHECK(submap1.theta > 0.005);
  // Its neighbour follows part of the way through the chain edge; submap 0 is the anchor and
  // its first scan, far from the closure, barely moves.
  CHECK(scanAt(g, 7).y > 0.05);
  CHECK(scanAt(g, 7).y < closed.y);
  CHECK(std::abs(scanAt(g, 0).y) < 0.03);
  CHECK(g.submapPoses().at(0).x == Approx(0).margin(1e-9));

  // The same closure under the Huber loss moves things less: 20 sigmas off, it is discounted.
  ScanGraphOptions huber = plain();
  huber.optimizer.ceres.huber_delta = ScanGraphOptions{}.optimizer.ceres.huber_delta;
  ScanGraph robust = twoSubmaps(huber);
  REQUIRE(robust.addLoop(loop, fallback));
  robust.optimize(kStart);
  CHECK(scanAt(robust, 8).y < closed.y - 0.05);
  CHECK(scanAt(robust, 8).y > 0.01);
}

TEST_CASE("scan graph: a closure's covariance is read in its matched submap's frame",
          "[scan_graph]") {
  // The scan at t = 8 s matched in submap 0 turned 90 degrees, loose along submap 0's x (1 m)
  // and tight along its y (1 cm). The edge must weigh those axes, whatever the scan's heading.
  ScanGraph g = twoSubmaps();
  auto [loop, fallback] = closure();
  loop.pose = Pose2(8, 0, std::numbers::pi / 2);
  loop.covariance = Eigen::Vector3d(1.0, 1e-4, 1e-4).asDiagonal();
  REQUIRE(g.addLoop(loop, fallback));
  g.optimize(kStart);
  REQUIRE(g.loopsOnScans() == 1);
  const auto& graph = g.graph();
  const auto edge = std::find_if(graph.edges.begin(), graph.edges.end(),
                                 [](const pose_graph::Edge2D& e) { return e.robust; });
  REQUIRE(edge != graph.edges.end());
  auto chi2Moved = [&](double dx, double dy) {
    pose_graph::Graph2D one;
    one.addNode(0, Eigen::Vector3d::Zero());
    one.addNode(1, pose_graph::compose(Eigen::Vector3d::Zero(), edge->measurement) +
                       Eigen::Vector3d(dx, dy, 0));
    one.edges.push_back({0, 1, edge->measurement, edge->information});
    return pose_graph::chi2(one);
  };
  CHECK(chi2Moved(0.1, 0) == Approx(0.01));
  CHECK(chi2Moved(0, 0.1) == Approx(100.0));
}

TEST_CASE("scan graph defaults: loose intra-submap edges let a closure pull its scan further",
          "[scan_graph]") {
  ScanGraph tight = twoSubmaps();
  ScanGraph loose = twoSubmaps(ScanGraphOptions{});
  // Submaps 0 and 1 share the scan at t = 4 s: by default their hand-over is left out.
  tight.optimize(kStart);
  loose.optimize(kStart);
  CHECK(tight.edges() == 19);  // 10 intra-submap, 8 chain, the hand-over
  CHECK(loose.edges() == 18);
  // A moderate disagreement (0.1 m, 5 sigmas: inside the Huber scale region it still pulls).
  auto [loop, fallback] = closure();
  loop.pose = Pose2(8, 0.1, 0);
  ScanGraph tight_closed = twoSubmaps(), loose_closed = twoSubmaps(ScanGraphOptions{});
  REQUIRE(tight_closed.addLoop(loop, fallback));
  REQUIRE(loose_closed.addLoop(loop, fallback));
  tight_closed.optimize(kStart);
  loose_closed.optimize(kStart);
  const double tight_y = scanAt(tight_closed, 8).y, loose_y = scanAt(loose_closed, 8).y;
  INFO("closed scan y: tight " << tight_y << ", loose " << loose_y);
  CHECK(loose_y > tight_y);
  CHECK(loose_y > 0.05);
}

TEST_CASE("scan graph: without chain edges only the closed scan and its submap move",
          "[scan_graph]") {
  ScanGraphOptions o = plain();
  o.chain_sigma_linear = 0;
  ScanGraph g = twoSubmaps(o);
  const auto [loop, fallback] = closure();
  REQUIRE(g.addLoop(loop, fallback));
  g.optimize(kStart);
  const Pose2 submap1 = g.submapPoses().at(1);
  // Every other scan of submap 1 is carried exactly by it.
  for (int s = 5; s <= 7; ++s) {
    const Pose2 in_own = submap1.inverse() * scanAt(g, s);
    CHECK(in_own.x == Approx(s - 4).margin(1e-6));
    CHECK(in_own.y == Approx(0).margin(1e-6));
  }
  CHECK(scanAt(g, 8).y > 0.2);
}

TEST_CASE("scan graph: scans between nodes are interpolated between their neighbouring nodes",
          "[scan_graph]") {
  ScanGraphOptions o = plain();
  o.node_every = 3;
  ScanGraph g = twoSubmaps(o);
  // Nodes: t = 0, 3, 4 (submap 0: every third and the last), 7, 8 (submap 1; t = 4 shared).
  g.optimize(kStart);
  CHECK(g.scanNodes() == 5);
  CHECK(scanAt(g, 5).x == Approx(5).margin(1e-6));
  CHECK(scanAt(g, 1).y == Approx(0).margin(1e-6));

  // A closure on a scan that is not an every-third one makes it a node.
  ScanGraph closed = twoSubmaps(o);
  auto [loop, fallback] = closure(6 * kSecond);
  loop.pose = Pose2(6, 0.3, 0);
  REQUIRE(closed.addLoop(loop, fallback));
  closed.optimize(kStart);
  CHECK(closed.scanNodes() == 6);
  CHECK(closed.loopsOnScans() == 1);
  // t = 5 lies between the nodes at 4 and 6: its offset lies between theirs.
  const double y4 = scanAt(closed, 4).y, y5 = scanAt(closed, 5).y, y6 = scanAt(closed, 6).y;
  CHECK(y6 > 0.1);
  CHECK(y5 > std::min(y4, y6));
  CHECK(y5 < std::max(y4, y6));
}

TEST_CASE("scan graph: a closure on a scan in no trajectory falls back to the submap level",
          "[scan_graph]") {
  ScanGraph g = twoSubmaps();
  const auto [loop, fallback] = closure(42 * kSecond);
  REQUIRE(g.addLoop(loop, fallback));
  g.optimize(kStart);
  CHECK(g.loopsOnScans() == 0);
  CHECK(g.loopsOnSubmaps() == 1);
  // The fused hand-over + revisit moved submap 1, and its scans with it: the closed one no
  // farther from its smoothed pose in submap 1 than the shared first scan (held by submap 0).
  const Pose2 submap1 = g.submapPoses().at(1);
  const Pose2 end = submap1 * Pose2(4, 0, 0);
  CHECK(end.y > 0.1);
  const Pose2 in_own = submap1.inverse() * scanAt(g, 8);
  const Pose2 shared_in_own = submap1.inverse() * scanAt(g, 4);
  CHECK(std::hypot(in_own.x - 4, in_own.y) <= std::hypot(shared_in_own.x, shared_in_own.y));
}

TEST_CASE("scan graph: warm restarts keep the optimum and place new submaps", "[scan_graph]") {
  ScanGraph g = twoSubmaps();
  const auto [loop, fallback] = closure();
  REQUIRE(g.addLoop(loop, fallback));
  const auto cold = g.optimize(kStart);
  const Pose2 first = scanAt(g, 8);
  // Again: the start map is ignored for the submaps already placed, nothing has to move.
  const std::map<int, Pose2> wrong{{0, Pose2(9, 9, 1)}, {1, Pose2(9, 9, 1)}};
  const auto again = g.optimize(wrong);
  CHECK(again.iterations < cold.iterations);
  CHECK(scanAt(g, 8).y == Approx(first.y).margin(1e-6));
  // A third submap: it starts where the start map says, then its hand-over places it.
  REQUIRE(g.addSubmap(2, straight(8)));
  SubmapConstraintInput c = handOver();
  c.from = 1;
  c.to = 2;
  REQUIRE(g.addConstraint(c));
  auto start = wrong;
  start[2] = g.submapPoses().at(1) * Pose2(4, 0, 0);
  g.optimize(start);
  CHECK(g.submaps() == 3);
  CHECK(g.scanNodes() == 13);
  CHECK(g.submapPoses().at(0).x == Approx(0).margin(1e-9));
  CHECK((g.submapPoses().at(2).translation() - start[2].translation()).norm() < 0.1);
}

TEST_CASE("scan graph: bad input is refused with the reason", "[scan_graph]") {
  ScanGraphOptions bad;
  bad.node_every = 0;
  CHECK_THROWS_AS(ScanGraph(bad), std::invalid_argument);
  bad = {};
  bad.intra_sigma_linear = 0;
  CHECK_THROWS_AS(ScanGraph(bad), std::invalid_argument);
  bad = {};
  bad.chain_sigma_linear = -1;
  CHECK_THROWS_AS(ScanGraph(bad), std::invalid_argument);

  ScanGraph g;
  auto backwards = straight(0);
  std::swap(backwards[1], backwards[2]);
  CHECK_FALSE(g.addSubmap(0, backwards));
  CHECK(g.lastError().find("do not increase") != std::string::npos);
  auto nan = straight(0);
  nan[3].pose.x = std::numeric_limits<double>::quiet_NaN();
  CHECK_FALSE(g.addSubmap(0, nan));
  CHECK(g.lastError().find("non-finite") != std::string::npos);
  REQUIRE(g.addSubmap(0, straight(0)));
  CHECK_FALSE(g.addSubmap(0, straight(0)));
  CHECK(g.lastError().find("added already") != std::string::npos);

  auto [loop, fallback] = closure();
  loop.covariance(0, 0) = -1;
  CHECK_FALSE(g.addLoop(loop, fallback));
  CHECK(g.lastError().find("positive definite") != std::string::npos);
  loop.covariance = covariance(0.02, 0.01);
  loop.pose.theta = std::numeric_limits<double>::infinity();
  CHECK_FALSE(g.addLoop(loop, fallback));
  SubmapConstraintInput self = handOver();
  self.to = 0;
  CHECK_FALSE(g.addConstraint(self));
  CHECK(g.lastError().find("itself") != std::string::npos);
  // Nothing to place: the solver refuses, the caller is told.
  ScanGraph empty;
  CHECK_THROWS_AS(empty.optimize({}), pose_graph::GraphError);
}

namespace {

void pushSubmap(ActorHarness& h, int id, const Pose2& origin,
                const std::vector<StampedPose2>& trajectory) {
  h.push<msg::Submap>("submaps", [&](auto& b) {
    test::fillSubmap(b, id, origin, trajectory.back().stamp_ns);
    auto t = b.initTrajectory(static_cast<unsigned>(trajectory.size()));
    for (unsigned i = 0; i < trajectory.size(); ++i) {
      t[i].setStampNs(trajectory[i].stamp_ns);
      t[i].setX(trajectory[i].pose.x);
      t[i].setY(trajectory[i].pose.y);
      t[i].setTheta(trajectory[i].pose.theta);
    }
  });
}

void pushConstraint(ActorHarness& h, std::int64_t stamp, const SubmapConstraintInput& c,
                    const ScanLoopInput* scan = nullptr, bool scan_covariance = true) {
  h.push<msg::SubmapConstraint>("constraints", [&](auto& b) {
    setHeader(b.initHeader(), stamp, "map", 0);
    b.setFromId(static_cast<std::uint32_t>(c.from));
    b.setToId(static_cast<std::uint32_t>(c.to));
    writePose(b.initRelative(), tessera::Pose2{c.relative.x, c.relative.y, c.relative.theta},
              &c.covariance);
    b.setKind(c.revisit ? msg::SubmapConstraint::Kind::REVISIT
                        : msg::SubmapConstraint::Kind::HAND_OVER);
    if (scan)
      writePose(b.initScanInTo(), tessera::Pose2{scan->pose.x, scan->pose.y, scan->pose.theta},
                scan_covariance ? &scan->covariance : nullptr);
  });
}

std::int64_t count(const Summary& s, const std::string& key) {
  return std::get<std::int64_t>(s.at(key));
}

}  // namespace

TEST_CASE("graph_optimizer with scan_graph takes the final trajectory from the scan nodes",
          "[scan_graph][graph_optimizer]") {
  laser_slam::GraphOptimizerActorOptions o;
  o.compose_trajectory = true;
  o.scan_graph.enabled = true;
  o.scan_graph.options = plain();  // the submaps carry their scans
  ActorHarness h(std::make_unique<laser_slam::GraphOptimizerActor>(o));
  pushSubmap(h, 0, Pose2(), straight(0));
  pushConstraint(h, 4 * kSecond, handOver());
  pushSubmap(h, 1, Pose2(4, 0, 0), straight(4));
  // The builder's final poses (chained map frame), one per scan.
  for (int s = 0; s <= 8; ++s)
    h.push<msg::PoseStamped>("trajectory", [&](auto& b) {
      setHeader(b.initHeader(), s * kSecond, "map", 0);
      writePose(b.initPose(), tessera::Pose2{double(s), 0.0, 0.0});
    });
  const auto [loop, fallback] = closure();
  pushConstraint(h, 8 * kSecond, fallback, &loop);
  pushConstraint(h, 8 * kSecond, fallback, &loop);  // re-sent: a duplicate, not a second edge
  // A closure whose scan pose lost its covariance: kept between submaps, and counted.
  auto [loop2, fallback2] = closure(7 * kSecond);
  loop2.pose = Pose2(7, 0.3, 0);
  fallback2.relative = Pose2(3, 0, 0) * loop2.pose.inverse();
  pushConstraint(h, 7 * kSecond, fallback2, &loop2, false);
  h.runUntilIdle();
  h.stop();

  const auto out = h.published<msg::PoseStamped>("trajectory_final");
  REQUIRE(out.size() == 9);
  // The closed scans moved toward their matches, the first one (next to the anchor) hardly.
  CHECK(std::abs(out[0]->getPose().getY()) < 0.05);
  CHECK(out[8]->getPose().getY() > 0.15);
  CHECK(out[7]->getPose().getY() > 0.1);
  const auto poses = h.published<msg::SubmapPoses>("submap_poses");
  REQUIRE(!poses.empty());
  REQUIRE(poses.back()->getPoses().size() == 2);
  Summary s;
  h.actor().summarize(s);
  CHECK(count(s, "scan_graph_optimized") == 1);
  CHECK(count(s, "scan_graph_scan_nodes") == 9);
  CHECK(count(s, "scan_graph_loops_on_scans") == 1);
  CHECK(count(s, "constraints_duplicate") == 1);
  CHECK(count(s, "scan_graph_rejected") == 1);
  CHECK(count(s, "scan_graph_poses_composed") == 0);
}

TEST_CASE("graph_optimizer refuses bad scan graph options", "[scan_graph][graph_optimizer]") {
  laser_slam::GraphOptimizerActorOptions o;
  o.scan_graph.options.node_every = 0;
  CHECK_THROWS_WITH(laser_slam::GraphOptimizerActor(o),
                    Catch::Contains("scan_graph.node_every must be >= 1"));
  o = {};
  o.scan_graph.options.intra_sigma_angular = -0.1;
  CHECK_THROWS_WITH(laser_slam::GraphOptimizerActor(o),
                    Catch::Contains("scan_graph.intra_sigma_angular must be > 0"));
  o = {};
  o.scan_graph.options.optimizer.ceres.max_iterations = 0;
  CHECK_THROWS_WITH(laser_slam::GraphOptimizerActor(o),
                    Catch::Contains("scan_graph.optimizer.ceres.max_iterations must be >= 1"));
  o = {};
  o.scan_graph.options.optimizer.ceres.huber_delta = -1;
  CHECK_THROWS_AS(laser_slam::GraphOptimizerActor(o), ConfigError);
}
