// KeyframeGraph (SE(3) keyframe pose graph): a square of keyframes whose odometry drifts, closed
// by one loop edge; a wrong loop edge held back by the Huber loss; bad input rejected.
#include <tessera/visual_slam/keyframe_graph.hpp>

#include <catch2/catch.hpp>

#include <algorithm>
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

namespace {

// `laps` times around square(): the path closes on itself, so keyframe k + 16 stands where k does.
std::vector<Pose3> squareLaps(int laps) {
  const auto lap = square();
  std::vector<Pose3> p;
  for (int l = 0; l < laps; ++l) p.insert(p.end(), lap.begin(), lap.end());
  return p;
}

KeyframeGraphOptions trimmingOptions() {
  KeyframeGraphOptions o = squareOptions();
  o.trimming.enabled = true;
  o.trimming.radius_m = 0.1;
  o.trimming.angle_rad = 0.1;
  o.trimming.min_age = 8;
  return o;
}

// Drives the laps with drifted odometry; each keyframe of a later lap is tied by a loop to the one
// it stands on a lap before, then the graph optimises and trims, as the keyframe_graph actor does.
struct LapRun {
  std::size_t loops_added = 0, loops_rejected = 0;
  std::vector<std::int64_t> trimmed;
};
LapRun driveLaps(KeyframeGraph& g, const std::vector<Pose3>& truth) {
  LapRun run;
  const auto tracked = drifted(truth);
  for (std::size_t k = 0; k < truth.size(); ++k) {
    REQUIRE(g.addKeyframe(static_cast<std::int64_t>(k), tracked[k], 100));
    if (k < 16) continue;
    const auto from = static_cast<std::int64_t>(k - 16);
    const auto outcome =
        g.addLoop(loop(from, static_cast<std::int64_t>(k), truth[k - 16].inverse() * truth[k]));
    if (outcome == Outcome::kAdded) ++run.loops_added;
    if (outcome == Outcome::kRejected) ++run.loops_rejected;
    if (!g.needsOptimization()) continue;
    g.optimize();
    for (const auto id : g.trim()) run.trimmed.push_back(id);
  }
  return run;
}

}  // namespace

TEST_CASE("KeyframeGraph: lifelong trimming keeps one lap of keyframes and the accuracy",
          "[visual_slam][graph][lifelong]") {
  const auto truth = squareLaps(3);
  KeyframeGraphOptions plain = trimmingOptions();
  plain.trimming.enabled = false;
  KeyframeGraph all(plain);
  const LapRun kept_all = driveLaps(all, truth);
  CHECK(all.keyframes() == 48);
  CHECK(kept_all.trimmed.empty());
  CHECK(all.trimmed() == 0);

  KeyframeGraph g(trimmingOptions());
  LapRun run = driveLaps(g, truth);
  // Each loop's older end is covered by its newer one once the loop is optimised: laps 1 and 2
  // leave, but for the anchor (keyframe 0, never trimmed); the last lap stays.
  CHECK(run.loops_added == 32);
  CHECK(run.loops_rejected == 0);
  CHECK(g.trimmed() == 31);
  REQUIRE(g.keyframes() == 17);
  CHECK(g.poses().count(0) == 1);
  for (std::int64_t id = 32; id < 48; ++id) CHECK(g.poses().count(id) == 1);
  std::vector<std::int64_t> expected;
  for (std::int64_t id = 1; id < 32; ++id) expected.push_back(id);
  std::sort(run.trimmed.begin(), run.trimmed.end());
  CHECK(run.trimmed == expected);
  // What the trimmed keyframes' edges said lives on in chained edges: the kept lap is placed
  // nearly as well as with every keyframe kept (the star drops correlations: 0.10 m against
  // 0.06 m), far better than without loops.
  const KeyframeGraph no_loops = squareGraph(plain, truth);
  const double error_all = maxError(all, truth), error_trimmed = maxError(g, truth);
  const double error_none = maxError(no_loops, truth);
  INFO("max position error with every keyframe " << error_all << " m, trimmed " << error_trimmed
                                                 << " m, without loops " << error_none << " m");
  CHECK(error_trimmed < 0.12);
  CHECK(error_trimmed < 2 * error_all);
  CHECK(error_trimmed < 0.25 * error_none);
  // The graph stays sparse: no more edges than a chain with a loop per kept keyframe.
  CHECK(g.graph().edges.size() <= 2 * g.keyframes());
}

TEST_CASE("KeyframeGraph: trimming spares recent keyframes and refuses loops to trimmed ones",
          "[visual_slam][graph][lifelong]") {
  KeyframeGraphOptions o = trimmingOptions();
  o.trimming.min_age = 20;
  KeyframeGraph g(o);
  const auto truth = squareLaps(2);
  const auto tracked = drifted(truth);
  for (std::size_t k = 0; k < truth.size(); ++k)
    REQUIRE(g.addKeyframe(static_cast<std::int64_t>(k), tracked[k], 100));
  // Keyframe 20 covers keyframe 4 once a loop has tied them: 16 apart, under min_age 20.
  REQUIRE(g.addLoop(loop(4, 20, truth[4].inverse() * truth[20])) == Outcome::kAdded);
  g.optimize();
  CHECK(g.trim().empty());
  // At min_age 16 the same graph gives keyframe 4 up.
  o.trimming.min_age = 16;
  KeyframeGraph h(o);
  for (std::size_t k = 0; k < truth.size(); ++k)
    REQUIRE(h.addKeyframe(static_cast<std::int64_t>(k), tracked[k], 100));
  REQUIRE(h.addLoop(loop(4, 20, truth[4].inverse() * truth[20])) == Outcome::kAdded);
  h.optimize();
  // Keyframe 4 and its neighbours, which the loop brought next to 16 keyframes later; but only
  // keyframes at least 16 older than the newest (31), and never the anchor.
  const auto gone = h.trim();
  CHECK(std::count(gone.begin(), gone.end(), 4) == 1);
  for (const auto id : gone) {
    CHECK(id >= 1);
    CHECK(id <= 15);
  }
  CHECK(h.keyframes() == 32 - gone.size());
  // A loop to it now (the detector had not heard yet) is refused, not left waiting.
  CHECK(h.addLoop(loop(4, 21, truth[4].inverse() * truth[21])) == Outcome::kRejected);
  CHECK_THAT(h.lastError(), Catch::Contains("keyframe 4 is no longer in the graph"));
  CHECK(h.pending() == 0);
  // Bad options name themselves.
  for (auto set : {+[](KeyframeGraphOptions& x) { x.trimming.radius_m = 0; },
                   +[](KeyframeGraphOptions& x) { x.trimming.angle_rad = std::nan(""); },
                   +[](KeyframeGraphOptions& x) { x.trimming.min_age = 0; }}) {
    KeyframeGraphOptions bad = trimmingOptions();
    set(bad);
    CHECK_THROWS_WITH(KeyframeGraph(bad), Catch::Contains("trimming."));
  }
}
