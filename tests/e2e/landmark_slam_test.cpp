// End to end: sim_landmarks (seed 004 world) with each filter; the SLAM trajectory must beat
// dead reckoning of the same noisy controls by a wide margin, and the map must be close.
#include <tessera/common/landmark_io.hpp>
#include <tessera/common/trajectory_io.hpp>
#include <tessera/common/trajectory_metrics.hpp>

#include <catch2/catch.hpp>

#include "../shared_data.hpp"
#include "run_profile.hpp"

#include <filesystem>
#include <string>

using namespace tessera;
namespace fs = std::filesystem;

TEST_CASE("sim_landmarks: both filters track far better than odometry", "[e2e][landmark_slam]") {
  for (const std::string filter : {"ekf", "rbekf"}) {
    INFO(filter);
    const fs::path out = test::scratchDir("e2e_sim_landmarks_" + filter);
    const RunReport report = test::runProfile("sim_landmarks", out, {"filter=" + filter, "seed=3"});
    const auto truth = common::readTum(out / "ground_truth.tum");
    const auto slam = common::computeAte(common::readTum(out / "trajectory.tum"), truth);
    const auto odom = common::computeAte(common::readTum(out / "odometry.tum"), truth);
    INFO("slam ATE " << slam.translation.rmse << " m, odometry " << odom.translation.rmse << " m");
    CHECK(slam.pairs > 300);
    CHECK(slam.translation.rmse < 0.25 * odom.translation.rmse);
    CHECK(slam.translation.rmse < 1.0);
    const auto lm =
        common::computeLandmarkError(common::readLandmarks(out / "landmarks.txt"),
                                     common::readLandmarks(out / "landmarks_truth.txt"));
    CHECK(lm.pairs >= 20);
    CHECK(lm.error.rmse < 1.0);
    const double nis = std::get<double>(test::summaryOf(report, "slam").at("mean_nis"));
    CHECK(nis > 0.5);
    CHECK(nis < 10);
  }
}
