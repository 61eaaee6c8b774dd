// The robot profiles on emulated hardware, through the drivers exactly as on the robot:
// robot_create_kinect plays 7-Scenes frames through libfreenect's own player (fakenect) with an
// emulated Create 2 on a pseudo-terminal, and tracks them as well as rgbd_slam does from the
// dataset folder (the Kinect path only adds the disparity quantisation); robot_pioneer_sick maps
// with an emulated SICK LMS200, VectorNav VN-100 and Create 2, each on its pseudo-terminal.
#include <tessera/drivers/create_device.hpp>
#include <tessera/drivers/emulator_host.hpp>
#include <tessera/drivers/sick_lms_device.hpp>
#include <tessera/drivers/vectornav_device.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iterator>

#include "../apps/cli_run.hpp"
#include "../shared_data.hpp"

namespace robot_profiles_test {

using namespace tessera;
namespace fs = std::filesystem;

/// The trajectory with stamps counted from its first pose.
std::vector<mapping::TumPose> fromFirst(std::vector<mapping::TumPose> poses) {
  REQUIRE_FALSE(poses.empty());
  const auto t0 = poses.front().stamp_ns;
  for (auto& p : poses) p.stamp_ns -= t0;
  return poses;
}

/// `estimate` on the clock of `reference`: the runs have different clocks, and the driver's
/// stamps follow the recording's frame counter only once its clock mapping has seen a few
/// frames (the first ones come in late), so the shift is the one that pairs the most poses.
std::vector<mapping::TumPose> onClockOf(std::vector<mapping::TumPose> estimate,
                                        const std::vector<mapping::TumPose>& reference,
                                        const evaluation::AssociationOptions& association) {
  REQUIRE_FALSE(estimate.empty());
  std::int64_t best_shift = 0;
  std::size_t best_pairs = 0;
  for (std::size_t i = 0; i < std::min<std::size_t>(10, estimate.size()); ++i)
    for (std::size_t j = 0; j < std::min<std::size_t>(20, reference.size()); ++j) {
      const std::int64_t shift = reference[j].stamp_ns - estimate[i].stamp_ns;
      auto shifted = estimate;
      for (auto& p : shifted) p.stamp_ns += shift;
      const auto pairs = evaluation::associateByTime(shifted, reference, association).size();
      if (pairs > best_pairs) {
        best_pairs = pairs;
        best_shift = shift;
      }
    }
  for (auto& p : estimate) p.stamp_ns += best_shift;
  return estimate;
}

TEST_CASE("robot_create_kinect tracks 7-Scenes played through fakenect as rgbd_slam does",
          "[e2e][drivers][kinect][serial]") {
  TESSERA_SHARED_DATA(dir, "7scenes-redkitchen-rgbd");
  const fs::path out = test::scratchDir("e2e_robot_kinect");
  const fs::path recording = out / "recording";
  constexpr int kFrames = 150;

  const auto emulated = test::runCli("emulate kinect --rgbd " + dir.string() + " --frames " +
                                         std::to_string(kFrames) + " --out " + recording.string(),
                                     out);
  INFO(emulated.err);
  REQUIRE(emulated.exit_code == 0);
  struct Cleanup {
    fs::path p;
    ~Cleanup() { fs::remove_all(p); }
  } cleanup{recording};  // 0.3 GB of frames

  // The reference: the dataset folder through the player (its clock follows the dataset's).
  const auto player = test::runCli("run rgbd_slam --set player.path=" + dir.string() +
                                       " --set player.last_frame=" + std::to_string(kFrames - 1) +
                                       " --out " + (out / "player").string(),
                                   out);
  INFO(player.err);
  REQUIRE(player.exit_code == 0);

  drivers::CreateDevice create;
  drivers::EmulatorHost host({[&](std::string_view b, std::int64_t t) { create.receive(b, t); },
                              [&](std::int64_t t) { return create.poll(t); },
                              [&] { return create.nextDue(); },
                              [&](std::int64_t t) { create.restart(t); },
                              {}},
                             drivers::EmulatorHostOptions{(out / "create").string(), -1, 115200});
  // Through the CLI: fakenect plays one recording per process.
  const auto robot =
      test::runCli("run robot_create_kinect --set camera.recording=" + recording.string() +
                       " --set camera.registration=none --set base.device=" + host.devicePath() +
                       " --out " + (out / "robot").string(),
                   out);
  INFO(robot.err);
  REQUIRE(robot.exit_code == 0);
  std::ifstream in(out / "robot" / "summary.json");
  REQUIRE(in);
  const auto summary = nlohmann::json::parse(in);
  INFO(summary.dump(2));
  const auto count = [&](const std::string& actor, const std::string& key) {
    return summary.at("actors").at(actor).at(key).get<std::int64_t>();
  };
  CHECK(count("camera", "frames") == kFrames);
  CHECK(count("camera", "dropped_unpaired") == 0);
  CHECK(count("front_end", "lost") == 0);
  // keep_latest(1): a frame that arrives while the front end is busy replaces the waiting one,
  // so how many are tracked depends on the machine: ~12 ms per frame on a quiet one, 40-50 ms
  // in this pipeline on a slow 2-core VM, where 106-113 of the 150 were tracked. Every frame is
  // either handled or counted as dropped, and well over half are tracked.
  const auto& rgbd = summary.at("actors").at("front_end").at("subscriptions").at("rgbd");
  CHECK(rgbd.at("handled").get<std::int64_t>() + rgbd.at("drops").get<std::int64_t>() == kFrames);
  CHECK(count("front_end", "frames") >= kFrames / 2);
  CHECK(count("base", "frames") > 50);  // the Create streamed meanwhile

  evaluation::AteOptions o;
  o.association.max_difference_s = 0.005;  // frames are 33 ms apart
  const auto truth = fromFirst(mapping::readTum(out / "player" / "ground_truth.tum"));
  const auto reference = fromFirst(mapping::readTum(out / "player" / "trajectory.tum"));
  const auto kinect =
      onClockOf(mapping::readTum(out / "robot" / "trajectory.tum"), truth, o.association);
  REQUIRE(truth.size() == kFrames);
  const auto ate_reference = evaluation::computeAte(reference, truth, o);
  const auto ate_kinect = evaluation::computeAte(kinect, truth, o);
  INFO("ATE player " << ate_reference.translation.rmse << " m over " << ate_reference.pairs
                     << " frames; kinect " << ate_kinect.translation.rmse << " m over "
                     << ate_kinect.pairs);
  CHECK(ate_kinect.pairs >= kFrames / 2);
  CHECK(ate_kinect.translation.rmse < ate_reference.translation.rmse + 0.02);
  CHECK(ate_kinect.translation.rmse < 0.08);
}

TEST_CASE("tessera emulate kinect refuses a missing or empty dataset and a used output folder",
          "[e2e][drivers][kinect]") {
  const fs::path out = test::scratchDir("e2e_emulate_kinect_bad");
  auto run = test::runCli(
      "emulate kinect --rgbd " + (out / "missing").string() + " --out " + (out / "rec").string(),
      out);
  CHECK(run.exit_code != 0);
  CHECK_THAT(run.err, Catch::Contains("--rgbd"));
  fs::create_directories(out / "empty");
  run = test::runCli(
      "emulate kinect --rgbd " + (out / "empty").string() + " --out " + (out / "rec").string(),
      out);
  CHECK(run.exit_code == 1);
  CHECK_THAT(run.err, Catch::Contains((out / "empty").string()));
  CHECK_FALSE(fs::exists(out / "rec"));
  TESSERA_SHARED_DATA(tum, "tum-rgbd-fr1-desk-9frames");
  fs::create_directories(out / "used");
  std::ofstream(out / "used" / "keep.txt") << "x";
  run = test::runCli("emulate kinect --rgbd " + tum.string() + " --out " + (out / "used").string(),
                     out);
  CHECK(run.exit_code == 1);
  CHECK_THAT(run.err, Catch::Contains("not empty"));
  CHECK(fs::exists(out / "used" / "keep.txt"));
  fs::remove_all(out);
}

/// A 5 x 3 m box around the LMS, which stands 1 m from its left wall (beams from the right,
/// counter-clockwise, in mm; 0 = no echo beyond 8 m).
std::vector<std::uint32_t> box(int angle_deg, int resolution_centideg) {
  const int n = angle_deg * 100 / resolution_centideg + 1;
  std::vector<std::uint32_t> mm(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) {
    const double a = (-angle_deg / 2.0 + k * resolution_centideg * 0.01) * M_PI / 180;
    const double c = std::cos(a), s = std::sin(a);
    double t = 1e9;
    if (c > 1e-9) t = std::min(t, 4.0 / c);    // the far wall, 4 m ahead
    if (s > 1e-9) t = std::min(t, 1.0 / s);    // left wall
    if (s < -1e-9) t = std::min(t, -2.0 / s);  // right wall
    mm[static_cast<std::size_t>(k)] =
        t > 8.0 ? 0u : static_cast<std::uint32_t>(std::lround(t * 1000));
  }
  return mm;
}

TEST_CASE("robot_pioneer_sick maps with an emulated LMS200, VN-100 and Create 2 until Ctrl-C",
          "[e2e][drivers]") {
  const fs::path out = test::scratchDir("e2e_robot_sick");
  using drivers::EmulatorHost;
  using drivers::EmulatorHostOptions;
  drivers::SickLmsDevice lms(box);
  EmulatorHost lms_host({[&](std::string_view b, std::int64_t t) { lms.receive(b, t); },
                         [&](std::int64_t t) { return lms.poll(t); }, [&] { return lms.nextDue(); },
                         [&](std::int64_t t) { lms.restart(t); }, [&] { return lms.baud(); }},
                        EmulatorHostOptions{(out / "lms").string(), -1, 9600});
  drivers::VectorNavDevice imu(115200);  // standing still: no turn
  EmulatorHost imu_host({[&](std::string_view b, std::int64_t t) { imu.receive(b, t); },
                         [&](std::int64_t t) { return imu.poll(t); }, [&] { return imu.nextDue(); },
                         [&](std::int64_t t) { imu.restart(t); }, [&] { return imu.baud(); }},
                        EmulatorHostOptions{(out / "imu").string(), -1, 115200});
  drivers::CreateDevice create;
  EmulatorHost create_host({[&](std::string_view b, std::int64_t t) { create.receive(b, t); },
                            [&](std::int64_t t) { return create.poll(t); },
                            [&] { return create.nextDue(); },
                            [&](std::int64_t t) { create.restart(t); },
                            {}},
                           EmulatorHostOptions{(out / "create").string(), -1, 115200});

  // A robot profile runs until Ctrl-C: SIGINT after 10 s, and the outputs are still written.
  const std::string command =
      "timeout --foreground --preserve-status -s INT 10 " + std::string(TESSERA_CLI_PATH) +
      " run robot_pioneer_sick --set laser.device=" + lms_host.devicePath() +
      " --set imu.device=" + imu_host.devicePath() +
      " --set base.device=" + create_host.devicePath() + " --out " + (out / "run").string() +
      " > " + (out / "stdout.txt").string() + " 2> " + (out / "stderr.txt").string();
  const int status = std::system(command.c_str());
  std::ifstream err_in(out / "stderr.txt");
  const std::string err((std::istreambuf_iterator<char>(err_in)), {});
  INFO(err);
  REQUIRE(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 130);  // 128 + SIGINT: stopped by Ctrl-C, outputs written
  std::ifstream in(out / "run" / "summary.json");
  REQUIRE(in);
  const auto summary = nlohmann::json::parse(in);
  INFO(summary.dump(2));
  const auto count = [&](const std::string& actor, const std::string& key) {
    return summary.at("actors").at(actor).at(key).get<std::int64_t>();
  };
  // 75 scans a second once the LMS runs at 500 kBd; 40 Hz VNYMR; the Create's 15 ms frames.
  CHECK(count("laser", "scans_published") > 200);
  CHECK(count("imu", "samples") > 150);
  CHECK(count("base", "frames") > 200);
  CHECK(count("odometry", "steps_with_gyro") > 100);
  CHECK(count("slam", "scans_read") > 100);
  CHECK(fs::exists(out / "run" / "map.pgm"));
  const auto trajectory = mapping::readTum(out / "run" / "trajectory.tum");
  REQUIRE_FALSE(trajectory.empty());
  // It stood still: the SLAM pose stays where it began.
  CHECK(trajectory.back().position.head<2>().norm() < 0.05);
}

}  // namespace robot_profiles_test
