#include <tessera/players/landmark_player.hpp>

#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/runtime/runtime.hpp>

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <numbers>

#include "../../shared_data.hpp"

using namespace tessera;
using tessera::players::LandmarkPlayerActor;
using tessera::players::LandmarkPlayerOptions;

namespace {

constexpr Nanos kMs = 1'000'000;

std::filesystem::path syntheticMrclam(bool with_ground_truth) {
  const auto dir = test::scratchDir(with_ground_truth ? "lm_player_gt" : "lm_player");
  std::ofstream(dir / "Barcodes.dat") << "# s b\n1 5\n2 14\n6 72\n7 27\n";
  std::ofstream(dir / "Landmark_Groundtruth.dat") << "6 1.5 2.5 0.001 0.002\n7 -1 0 0 0\n";
  std::ofstream(dir / "Robot1_Odometry.dat") << "100.000 0.1 0.2\n100.010 0.3 -0.1\n"
                                                "100.030 0 0\n";
  std::ofstream(dir / "Robot1_Measurement.dat")
      << "100.010 72 2.0 0.1\n100.010 14 3.0 -0.2\n100.020 27 1.0 4.0\n100.040 14 1 0\n";
  if (with_ground_truth)
    std::ofstream(dir / "Robot1_Groundtruth.dat") << "99.995 0 0 0\n100.010 1 0 0.5\n";
  return dir;
}

LandmarkPlayerOptions mrclamOptions(const std::filesystem::path& dir) {
  LandmarkPlayerOptions o;
  o.format = "mrclam";
  o.path = dir.string();
  o.robot = 1;
  o.range_std = 0.05;
  o.bearing_std = 0.01;
  return o;
}

template <typename T>
std::vector<Nanos> stamps(const std::vector<Message<T>>& ms) {
  std::vector<Nanos> out;
  for (const auto& m : ms) out.push_back(m->getHeader().getStampNs());
  return out;
}

std::string configError(const LandmarkPlayerOptions& o) {
  try {
    LandmarkPlayerActor a(o);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("LandmarkPlayer: MRCLAM rows play at their dataset times on every topic",
          "[players][landmarks]") {
  const auto dir = syntheticMrclam(true);
  auto actor = std::make_unique<LandmarkPlayerActor>(mrclamOptions(dir));
  CHECK(actor->eventCount() == 10);  // map, 2 ground truth, 3 controls, 2 + 2 scans
  ActorHarness h(std::move(actor));
  h.advance(kNanosPerSecond);

  // Time zero is the earliest record: the ground truth at 99.995 s.
  const auto map = h.published<msg::LandmarkMap>("landmark_map");
  REQUIRE(map.size() == 1);
  CHECK(map[0]->getHeader().getStampNs() == 0);
  CHECK(std::string(map[0]->getHeader().getFrameId().cStr()) == "map");
  REQUIRE(map[0]->getLandmarks().size() == 2);
  CHECK(map[0]->getLandmarks()[0].getId() == 0);
  CHECK(map[0]->getLandmarks()[0].getX() == 1.5);
  CHECK(map[0]->getLandmarks()[0].getCovariance()[0] == Approx(1e-6));
  CHECK(map[0]->getLandmarks()[0].getCovariance()[3] == Approx(4e-6));
  CHECK(map[0]->getLandmarks()[1].getX() == -1);

  const auto gt = h.published<msg::GroundTruthPose>("ground_truth");
  CHECK(stamps(gt) == std::vector<Nanos>{0, 15 * kMs});
  CHECK(gt[1]->getPose().getTheta() == 0.5);

  const auto control = h.published<msg::DriveControl>("control");
  CHECK(stamps(control) == std::vector<Nanos>{5 * kMs, 15 * kMs, 35 * kMs});
  CHECK(control[0]->getSpeed() == 0.1);
  CHECK(control[0]->getTurnRate() == 0.2);
  CHECK(control[0]->getSteering() == 0.0);
  CHECK(control[0]->getWheelbase() == 0.0);
  CHECK(control[0]->getDtS() == Approx(0.010));
  CHECK(control[1]->getDtS() == Approx(0.020));
  CHECK(control[2]->getDtS() == 0.0);
  CHECK(control[1]->getHeader().getSeq() == 1);

  const auto scans = h.published<msg::LandmarkScan>("landmarks");
  REQUIRE(stamps(scans) == std::vector<Nanos>{15 * kMs, 25 * kMs});
  REQUIRE(scans[0]->getObservations().size() == 1);  // the robot seen at 15 ms is not here
  const auto o0 = scans[0]->getObservations()[0];
  CHECK(o0.getId() == 0);
  CHECK(o0.getRange() == 2.0);
  CHECK(o0.getBearing() == 0.1);
  CHECK(o0.getRangeStd() == 0.05);
  CHECK(o0.getBearingStd() == 0.01);
  CHECK(std::string(scans[0]->getHeader().getFrameId().cStr()) == "camera");
  const auto o1 = scans[1]->getObservations()[0];
  CHECK(o1.getId() == 1);
  CHECK(o1.getBearing() == Approx(4.0 - 2 * std::numbers::pi));  // wrapped into (-pi, pi]

  const auto robots = h.published<msg::LandmarkScan>("robots");
  REQUIRE(stamps(robots) == std::vector<Nanos>{15 * kMs, 45 * kMs});
  CHECK(robots[0]->getObservations()[0].getId() == 2);  // robot subject number
  CHECK(robots[0]->getObservations()[0].getRange() == 3.0);

  // Finished: nothing more, however long we wait.
  h.advance(100 * kNanosPerSecond);
  CHECK(h.publishedCount("control") == 3);
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<std::int64_t>(s.at("controls_published")) == 3);
  CHECK(std::get<std::int64_t>(s.at("observations_published")) == 2);
  CHECK(std::get<std::int64_t>(s.at("robot_scans_published")) == 2);
  CHECK(std::get<double>(s.at("data_duration_s")) == Approx(0.045));
}

TEST_CASE("LandmarkPlayer: a finite source that ends the run by itself", "[players][landmarks]") {
  RuntimeOptions ro;
  ro.show_progress = false;
  ro.threads = 2;
  Runtime rt(ro);
  rt.add("player", std::make_unique<LandmarkPlayerActor>(mrclamOptions(syntheticMrclam(false))));
  rt.configure();
  const RunReport report = rt.run();
  CHECK(report.stop_reason == "all inputs finished");
  CHECK(report.actors.at(0).messages_out == 8);  // no ground_truth topic without the file
  CHECK(report.sim_duration_s == Approx(0.04));  // from 100.000 s to 100.040 s
}

TEST_CASE("LandmarkPlayer: Victoria Park poses play at a fixed step with dense landmark ids",
          "[players][landmarks]") {
  const auto dir = test::scratchDir("lm_player_victoria");
  const std::string noise = " 0.0001 0 0 4e-06 0 4e-06\n";
  std::ofstream(dir / "v.txt") << "ODOMETRY 0 1 1 0 1.5707963267948966" << noise
                               << "LANDMARK 1 7 3 4 0.4 0 0.4\n"
                               << "LANDMARK 1 2 0 -2 0.4 0 0.4\n"
                               << "ODOMETRY 1 3 2 0 0" << noise;
  LandmarkPlayerOptions o;
  o.format = "victoria";
  o.path = (dir / "v.txt").string();
  o.victoria_step_s = 0.5;
  ActorHarness h(std::make_unique<LandmarkPlayerActor>(o));
  h.advance(10 * kNanosPerSecond);

  const auto odom = h.published<msg::Odometry>("odom");
  REQUIRE(stamps(odom) == std::vector<Nanos>{0, 500 * kMs, 1000 * kMs});
  const tessera::Pose2 p2 = toPose2(odom[2]->getPose());
  CHECK(p2.x == Approx(1));
  CHECK(p2.y == Approx(2));  // 2 m ahead after turning left by 90 degrees
  CHECK(p2.theta == Approx(std::numbers::pi / 2));
  CHECK(odom[1]->getTwist().getOmega() == Approx(std::numbers::pi));  // (pi/2) / 0.5 s
  CHECK(odom[1]->getTwistCovariance()[0] == Approx(0.0001 / 0.25));
  CHECK(odom[0]->getPose().getCovariance().size() == 0);

  const auto control = h.published<msg::DriveControl>("control");
  REQUIRE(stamps(control) == std::vector<Nanos>{0, 500 * kMs});
  CHECK(control[0]->getTurnRate() == Approx(std::numbers::pi));
  // Arc with chord 1 m and a quarter turn: length = 1 * (pi/4) / sin(pi/4).
  CHECK(control[0]->getSpeed() ==
        Approx((std::numbers::pi / 4) / std::sin(std::numbers::pi / 4) / 0.5));
  CHECK(control[1]->getSpeed() == Approx(4.0));
  CHECK(control[1]->getDtS() == 0.5);

  const auto scans = h.published<msg::LandmarkScan>("landmarks");
  REQUIRE(stamps(scans) == std::vector<Nanos>{500 * kMs});
  REQUIRE(scans[0]->getObservations().size() == 2);
  CHECK(scans[0]->getObservations()[0].getId() == 1);  // landmark id 7 -> index 1
  CHECK(scans[0]->getObservations()[0].getRange() == Approx(5));
  CHECK(scans[0]->getObservations()[1].getId() == 0);  // landmark id 2 -> index 0
  CHECK(scans[0]->getObservations()[1].getBearing() == Approx(-std::numbers::pi / 2));
  CHECK(scans[0]->getObservations()[1].getBearingStd() == Approx(0.2));
  CHECK(std::string(scans[0]->getHeader().getFrameId().cStr()) == "laser");
  CHECK(h.publishedCount("landmark_map") == 0);
}

TEST_CASE("LandmarkPlayer: bad options and bad datasets are ConfigErrors naming them",
          "[players][landmarks]") {
  LandmarkPlayerOptions o = mrclamOptions(syntheticMrclam(false));
  o.format = "kitti";
  CHECK_THAT(configError(o), Catch::Contains("'format'"));
  o = mrclamOptions(syntheticMrclam(false));
  o.robot = 7;
  CHECK_THAT(configError(o), Catch::Contains("'robot'"));
  o.robot = 2;  // no Robot2 files
  CHECK_THAT(configError(o), Catch::Contains("'path'") && Catch::Contains("Robot2_Odometry.dat"));
  o.path = "";
  CHECK_THAT(configError(o), Catch::Contains("'path'"));
  o = mrclamOptions(syntheticMrclam(false));
  o.range_std = -1;
  CHECK_THAT(configError(o), Catch::Contains("'range_std'"));
  LandmarkPlayerOptions v;
  v.format = "victoria";
  v.path = "/nonexistent.txt";
  CHECK_THAT(configError(v), Catch::Contains("/nonexistent.txt"));
  v.victoria_step_s = 0;
  CHECK_THAT(configError(v), Catch::Contains("'victoria_step_s'"));

  // Loaded from YAML through the registry: unknown keys are rejected.
  CHECK_THROWS_AS(ActorRegistry::instance().create(
                      "landmark_player", Params(YAML::Load("{format: mrclam, speed: 3}"), "t")),
                  ConfigError);
  CHECK(ActorRegistry::instance().find("landmark_player") != nullptr);
}

TEST_CASE("LandmarkPlayer: real MRCLAM robot 1 publishes every row", "[players][landmarks]") {
  TESSERA_SHARED_DATA(folder, "utias-mrclam-dataset1");
  LandmarkPlayerOptions o;
  o.path = folder.string();
  o.robot = 1;
  ActorHarness h(std::make_unique<LandmarkPlayerActor>(o));
  h.advance(2000 * kNanosPerSecond);  // the recording lasts about 1491 s
  CHECK(h.publishedCount("control") == 97890);
  CHECK(h.publishedCount("landmarks") == 3518);  // distinct times with a landmark sighting
  CHECK(h.publishedCount("robots") == 830);
  CHECK(h.publishedCount("landmark_map") == 1);
  std::size_t observations = 0;
  Nanos last = -1;
  for (const auto& s : h.published<msg::LandmarkScan>("landmarks")) {
    observations += s->getObservations().size();
    CHECK(s->getHeader().getStampNs() > last);
    last = s->getHeader().getStampNs();
  }
  CHECK(observations == 4771);
  Summary s;
  h.actor().summarize(s);
  CHECK(std::get<double>(s.at("data_duration_s")) == Approx(1490.478).margin(0.001));
}

TEST_CASE("LandmarkPlayer: real Victoria Park publishes every pose and sighting",
          "[players][landmarks]") {
  TESSERA_SHARED_DATA(path, "victoria-park-gtsam/victoria_park.txt");
  LandmarkPlayerOptions o;
  o.format = "victoria";
  o.path = path.string();
  ActorHarness h(std::make_unique<LandmarkPlayerActor>(o));
  h.advance(3600 * kNanosPerSecond);
  CHECK(h.publishedCount("odom") == 6969);
  CHECK(h.publishedCount("control") == 6968);
  CHECK(h.publishedCount("landmarks") == 3331);  // distinct poses with sightings
  std::size_t observations = 0;
  std::int32_t max_id = 0;
  for (const auto& s : h.published<msg::LandmarkScan>("landmarks")) {
    for (const auto ob : s->getObservations()) {
      ++observations;
      max_id = std::max(max_id, ob.getId());
    }
  }
  CHECK(observations == 3640);
  CHECK(max_id == 150);
  const auto odom = h.published<msg::Odometry>("odom");
  CHECK(odom.back()->getHeader().getStampNs() == 6968 * 200 * kMs);
}
