// KeyframeGraph (SE(3) keyframe pose graph): a square of keyframes whose odometry drifts, closed
// by one loop edge; a wrong loop edge held back by the Huber loss; bad input rejected.
#include <tessera/visual_slam/keyframe_graph.hpp>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

using namespace tessera;
using tessera::visual_slam::KeyframeGraph;
using tessera::visual_slam::KeyframeGraphOptions;
using tessera::visual_slam::LoopConstraint;
using Outcome = KeyframeGraph::Outcome;

namespace {

// A turn about the optical y axis (down): a yaw of a camera carried level.
Pose3 yaw(double angle) {
  return {Eigen::Vector3d::Zero(),
          Eigen::Quaterniond(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitY()))};
}
Pose3 forward(double metres) {
  return {Eigen::Vector3d(0, 0, metres), Eigen::Quaterniond::Identity()};
}

// 16 keyframes around a 2 m square: 0.5 m steps, a 90 degree turn after every fourth. The last
// keyframe is one step short of the first, facing it.
std::vector<Pose3> square() {
  std::vector<Pose3> p;
  Pose3 at;
  for (int i = 0; i < 16; ++i) {
    p.push_back(at);
    at = at * forward(0.5) * (i % 4 == 3 ? yaw(std::numbers::pi / 2) : Pose3{});
  }
  return p;
}

// The tracker's poses: each step's turn 1.5 degrees too large and its length 2 % too long.
std::vector<Pose3> drifted(const std::vector<Pose3>& truth) {
  std::vector<Pose3> p{truth.front()};
  for (std::size_t i = 1; i < truth.size(); ++i) {
    Pose3 step = truth[i - 1].inverse() * truth[i];
    step.t *= 1.02;
    p.push_back(p.back() * step * yaw(1.5 * std::numbers::pi / 180));
  }
  return p;
}

LoopConstraint loop(std::int64_t from, std::int64_t to, const Pose3& relative,
                    double sigma = 0.01) {
  LoopConstraint c;
  c.from = from;
  c.to = to;
  c.relative = relative;
  c.covariance = Eigen::Matrix<double, 6, 6>::Identity() * sigma * sigma;
  return c;
}

double maxError(const KeyframeGraph& g, const std::vector<Pose3>& truth) {
  double worst = 0;
  for (const auto& [id, p] : g.poses())
    worst = std::max(worst, (p.t - truth[static_cast<std::size_t>(id)].t).norm());
  return worst;
}

// Odometry uncertainty that matches the drift of drifted() (1 cm and 1.5 degrees per step): a
// loop edge is then consistent with the chain, as a true loop is with a tracker's real drift.
KeyframeGraphOptions squareOptions() {
  KeyframeGraphOptions o;
  o.odometry_sigma_translation = 0.02;
  o.odometry_sigma_rotation = 0.03;
  return o;
}

KeyframeGraph squareGraph(const KeyframeGraphOptions& o, const std::vector<Pose3>& truth) {
  KeyframeGraph g(o);
  const auto tracked = drifted(truth);
  for (std::size_t i = 0; i < tracked.size(); ++i)
    REQUIRE(g.addKeyframe(static_cast<std::int64_t>(i), tracked[i], 100));
  return g;
}

}  // namespace

TEST_CASE("KeyframeGraph: one loop edge takes out the drift of a square", "[visual_slam][graph]") {
  const auto truth = square();
  KeyframeGraph g = squareGraph(squareOptions(), truth);
  CHECK(g.keyframes() == 16);
  CHECK(g.graph().edges.size() == 15);
  CHECK(g.graph().fixed[0]);
  CHECK_FALSE(g.needsOptimization());
  const double before = maxError(g, truth);
  CHECK(before > 0.4);  // the drift the loop has to take out

  REQUIRE(g.addLoop(loop(15, 0, truth[15].inverse() * truth[0])) == Outcome::kAdded);
  CHECK(g.needsOptimization());
  const auto s = g.optimize();
  CHECK_FALSE(g.needsOptimization());
  CHECK(s.final_chi2 < s.initial_chi2);
  const double after = maxError(g, truth);
  INFO("max position error before " << before << " m, after " << after << " m");
  CHECK(after < 0.15 * before);  // 0.47 m -> 0.05 m (the bias is spread, not removed)
  // The first keyframe anchors the world frame.
  CHECK((g.poses().at(0).t - truth[0].t).norm() < 1e-9);
}

TEST_CASE("KeyframeGraph: a wrong loop edge is down-weighted by the Huber loss",
          "[visual_slam][graph]") {
  const auto truth = square();
  const Pose3 good = truth[15].inverse() * truth[0];
  // Keyframe 8 "recognised" as keyframe 0 seen from 1 m away: 2 m off the truth.
  const Pose3 wrong = forward(1.0);
  double error_huber = 0, error_plain = 0, error_good_only = 0;
  for (const double delta : {1.0, 0.0}) {
    KeyframeGraphOptions o = squareOptions();
    o.optimizer.ceres.huber_delta = delta;
    KeyframeGraph g = squareGraph(o, truth);
    REQUIRE(g.addLoop(loop(15, 0, good)) == Outcome::kAdded);
    g.optimize();
    if (delta > 0) error_good_only = maxError(g, truth);
    REQUIRE(g.addLoop(loop(8, 0, wrong)) == Outcome::kAdded);
    g.optimize();
    (delta > 0 ? error_huber : error_plain) = maxError(g, truth);
  }
  INFO("good loop only " << error_good_only << " m; plus a wrong one: Huber " << error_huber
                         << " m, plain least squares " << error_plain << " m");
  CHECK(error_plain > 0.5);
  CHECK(error_huber < 0.5 * error_plain);
  CHECK(error_huber < error_good_only + 0.15);
}

TEST_CASE("KeyframeGraph: bad keyframes and loops are refused, early loops wait",
          "[visual_slam][graph]") {
  KeyframeGraph g({});
  const double nan = std::numeric_limits<double>::quiet_NaN();
  CHECK_FALSE(g.addKeyframe(0, {Eigen::Vector3d(nan, 0, 0), Eigen::Quaterniond::Identity()}));
  CHECK(g.lastError().find("not finite") != std::string::npos);
  REQUIRE(g.addKeyframe(0, {}));
  CHECK_FALSE(g.addKeyframe(0, forward(1)));
  CHECK(g.lastError().find("added before") != std::string::npos);
  REQUIRE(g.addKeyframe(1, forward(0.5)));

  CHECK(g.addLoop(loop(1, 1, {})) == Outcome::kRejected);
  LoopConstraint bad = loop(1, 0, forward(-0.5));
  bad.covariance(0, 0) = -1;
  CHECK(g.addLoop(bad) == Outcome::kRejected);
  CHECK(g.lastError().find("positive definite") != std::string::npos);
  bad = loop(1, 0, forward(-0.5));
  bad.relative.t.x() = nan;
  CHECK(g.addLoop(bad) == Outcome::kRejected);
  CHECK(g.loops() == 0);

  // A loop naming a keyframe to come waits for it, then triggers an optimisation.
  CHECK(g.addLoop(loop(2, 0, forward(-1.0))) == Outcome::kPending);
  CHECK(g.pending() == 1);
  CHECK_FALSE(g.needsOptimization());
  REQUIRE(g.addKeyframe(2, forward(1.02)));
  CHECK(g.pending() == 0);
  CHECK(g.loops() == 1);
  REQUIRE(g.needsOptimization());
  g.optimize();
  CHECK(std::abs(g.poses().at(2).t.z() - 1.0) < 0.015);  // between odometry (1.02) and loop (1.0)

  KeyframeGraphOptions o;
  o.odometry_sigma_rotation = 0;
  CHECK_THROWS_WITH(KeyframeGraph(o), Catch::Contains("odometry_sigma_rotation"));
  o = {};
  o.optimizer.ceres.max_iterations = 0;
  CHECK_THROWS_WITH(KeyframeGraph(o), Catch::Contains("optimizer.ceres.max_iterations"));
}
