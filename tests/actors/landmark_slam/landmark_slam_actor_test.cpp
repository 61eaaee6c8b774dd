// The landmark_slam actor through the mock-mailbox harness: controls and scans in, poses and
// the landmark estimate out, truth-based figures and rejection counts in the summary.
#include <tessera/landmark_slam/landmark_slam_actor.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/options.hpp>

#include <yaml-cpp/yaml.h>
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

using namespace tessera;
using namespace tessera::landmark_slam;

namespace {

constexpr Nanos kStep = 100'000'000;  // 0.1 s

struct Lm {
  int id;
  double x, y;
};
const std::vector<Lm> kLandmarks{{0, 5, 2}, {1, 6, -3}, {2, 12, 1}};

void pushControl(ActorHarness& h, Nanos stamp, double speed, double dt) {
  h.push<msg::DriveControl>("control", [&](auto& b) {
    setHeader(b.initHeader(), stamp, "base_link", 0);
    b.setSpeed(speed);
    b.setWheelbase(0);
    b.setTurnRate(0);
    b.setDtS(dt);
  });
}

// Noise-free sightings of every landmark from (x, 0, 0), plus optional extra raw observations.
void pushScan(ActorHarness& h, Nanos stamp, double x,
              std::vector<std::array<double, 3>> extra = {}) {
  h.push<msg::LandmarkScan>("landmarks", [&](auto& b) {
    setHeader(b.initHeader(), stamp, "sensor", 0);
    auto obs = b.initObservations(static_cast<unsigned>(kLandmarks.size() + extra.size()));
    unsigned k = 0;
    for (const auto& l : kLandmarks) {
      obs[k].setId(l.id);
      obs[k].setRange(std::hypot(l.x - x, l.y));
      obs[k].setBearing(std::atan2(l.y, l.x - x));
      ++k;
    }
    for (const auto& e : extra) {
      obs[k].setId(static_cast<int>(e[0]));
      obs[k].setRange(e[1]);
      obs[k].setBearing(e[2]);
      ++k;
    }
  });
}

void pushTruth(ActorHarness& h, Nanos stamp, double x) {
  h.push<msg::GroundTruthPose>("ground_truth", [&](auto& b) {
    setHeader(b.initHeader(), stamp, "map", 0);
    auto p = b.initPose();
    p.setX(x);
    p.setY(0);
    p.setTheta(0);
  });
}

}  // namespace

TEST_CASE("landmark_slam actor tracks a straight drive and reports its figures",
          "[landmark_slam][actor]") {
  for (const FilterType filter : {FilterType::kEkf, FilterType::kRbEkf}) {
    INFO(detail::enumName(filter));
    // Noise-free data: the EKF stays exact. The UKF predicts the mean of the motion under
    // control noise, a little short of the noise-free step (E[cos(theta + e)] < cos(theta)), so
    // it is only close.
    const double tol = filter == FilterType::kEkf ? 1e-6 : 3e-3;
    LandmarkSlamActorOptions o;
    o.filter = filter;
    o.ground_truth = true;
    o.landmark_truth = true;
    o.estimator.sigma_turn_rate = kDegree;
    ActorHarness h(std::make_unique<LandmarkSlamActor>(o));
    h.push<msg::LandmarkMap>("landmark_truth", [&](auto& b) {
      setHeader(b.initHeader(), 0, "map", 0);
      auto list = b.initLandmarks(static_cast<unsigned>(kLandmarks.size()));
      for (unsigned i = 0; i < kLandmarks.size(); ++i) {
        list[i].setId(kLandmarks[i].id);
        list[i].setX(kLandmarks[i].x);
        list[i].setY(kLandmarks[i].y);
      }
    });
    // 1 m/s along x; the control at t covers [t, t + 0.1 s). The scan at t is pushed after the
    // control at t (the actor must still use it before that control).
    const double nan = std::numeric_limits<double>::quiet_NaN();
    for (int k = 0; k <= 20; ++k) {
      const Nanos t = k * kStep;
      pushTruth(h, t, 0.1 * k);
      if (k < 20) pushControl(h, t, 1.0, 0.1);
      if (k % 5 == 0)
        pushScan(h, t, 0.1 * k,
                 k == 10 ? std::vector<std::array<double, 3>>{{1, nan, 0}, {-1, 3, 0}, {2, -2, 0}}
                         : std::vector<std::array<double, 3>>{});
      h.runUntilIdle();
    }
    h.stop();

    const auto poses = h.published<msg::PoseStamped>("pose");
    REQUIRE(poses.size() == 5);
    CHECK(poses.back()->getHeader().getStampNs() == 20 * kStep);
    CHECK(poses.back()->getPose().getX() == Approx(2.0).margin(tol));
    CHECK(std::abs(poses.back()->getPose().getY()) < tol);
    CHECK(poses.back()->getPose().getCovariance().size() == 9);
    const auto maps = h.published<msg::LandmarkMap>("landmark_estimate");
    REQUIRE(maps.size() == 1);
    REQUIRE(maps.back()->getLandmarks().size() == 3);
    CHECK(maps.back()->getLandmarks()[2].getX() == Approx(12).margin(tol));
    CHECK(maps.back()->getLandmarks()[2].getCovariance().size() == 4);

    Summary s;
    h.actor().summarize(s);
    CHECK(std::get<std::int64_t>(s.at("scans")) == 5);
    CHECK(std::get<std::int64_t>(s.at("landmarks")) == 3);
    CHECK(std::get<std::int64_t>(s.at("corrections")) == 12);
    CHECK(std::get<std::int64_t>(s.at("rejected_non_finite")) == 1);
    CHECK(std::get<std::int64_t>(s.at("rejected_unknown_id")) == 1);
    CHECK(std::get<std::int64_t>(s.at("rejected_negative_range")) == 1);
    CHECK(std::get<std::int64_t>(s.at("ate_pairs")) == 5);
    CHECK(std::get<double>(s.at("ate_rmse_m")) < tol);
    CHECK(std::get<double>(s.at("landmark_rmse_m")) < tol);
    CHECK(std::get<std::int64_t>(s.at("landmark_pairs")) == 3);
    CHECK(std::get<double>(s.at("mean_nis")) >= 0);
  }
}

TEST_CASE("landmark_slam actor rejects bad options", "[landmark_slam][actor]") {
  LandmarkSlamActorOptions o;
  o.estimator.range_std = -1;
  CHECK_THROWS_WITH(LandmarkSlamActor(o), Catch::Contains("estimator.range_std"));
  o = {};
  o.estimator.initial_pose = {1, 2};
  CHECK_THROWS_WITH(LandmarkSlamActor(o), Catch::Contains("estimator.initial_pose"));
  o = {};
  o.estimator.unscented.alpha = 0;
  CHECK_THROWS_WITH(LandmarkSlamActor(o), Catch::Contains("estimator.unscented.alpha"));
}

TEST_CASE("landmark_slam options: the filter's keys in `estimator`, enums by name",
          "[landmark_slam][actor][options]") {
  const auto load = [](const std::string& yaml) {
    return loadOptions<LandmarkSlamActorOptions>(Params(YAML::Load(yaml), "test"));
  };
  const auto o = load(
      "filter: ekf\nestimator: {association: nearest, bearing_std: 0.05, unscented: {alpha: "
      "0.5}}\n");
  CHECK(o.filter == FilterType::kEkf);
  CHECK(o.estimator.association == Association::kNearestNeighbour);
  CHECK(o.estimator.bearing_std == 0.05);
  CHECK(o.estimator.unscented.alpha == 0.5);
  CHECK(o.estimator.range_std == LandmarkSlamOptions{}.range_std);
  CHECK_THROWS_WITH(load("filter: fastslam\n"), Catch::Contains("ekf | rbekf"));
  CHECK_THROWS_WITH(load("estimator: {association: guess}\n"), Catch::Contains("known | nearest"));
  CHECK_THROWS_WITH(load("sigma_steer_deg: 3\n"),
                    Catch::Contains("moved to estimator.sigma_steer"));
  CHECK_THROWS_WITH(load("association: known\n"),
                    Catch::Contains("moved to estimator.association"));
}
