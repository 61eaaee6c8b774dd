// tessera batch end to end on 7-Scenes RedKitchen frames 0-179: three shards tracked by worker
// processes and joined by the reduce give the one-process keyframe accuracy; the same shards run
// one by one (as separate hosts would) and reduced apart give the same keyframes; bad requests
// are refused by name.
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>

#include <nlohmann/json.hpp>

#include <fstream>
#include <iterator>

#include "../apps/cli_run.hpp"
#include "../shared_data.hpp"

using namespace tessera;
namespace fs = std::filesystem;

namespace batch_e2e {

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

double keyframeAte(const fs::path& out) {
  evaluation::AteOptions o;
  o.dimension = evaluation::Dimension::kSpatial;
  return evaluation::computeAte(mapping::readTum(out / "keyframes.tum"),
                                mapping::readTum(out / "ground_truth.tum"), o)
      .translation.rmse;
}

nlohmann::json readJson(const fs::path& p) {
  std::ifstream in(p);
  REQUIRE(in);
  return nlohmann::json::parse(in);
}

}  // namespace batch_e2e

using namespace batch_e2e;

TEST_CASE("tessera batch joins shards of 7-Scenes as accurately as one process",
          "[e2e][batch][rgbd]") {
  TESSERA_SHARED_DATA(data, "7scenes-redkitchen-rgbd");
  const fs::path dir = test::scratchDir("e2e_batch");
  const std::string sets =
      " --set player.path=" + data.string() + " --set player.last_frame=179 --quiet --threads 2";

  const auto one = test::runCli("run rgbd_slam --out " + (dir / "one").string() + sets, dir);
  INFO(one.err);
  REQUIRE(one.exit_code == 0);
  const double ate_one = keyframeAte(dir / "one");

  const fs::path all = dir / "all";
  const auto batch =
      test::runCli("batch rgbd_slam --workers 2 --shards 3 --out " + all.string() + sets, dir);
  INFO(batch.err);
  REQUIRE(batch.exit_code == 0);
  CHECK_THAT(batch.err, Catch::Contains("shard 2 (frames 120-179) done"));
  const auto plan = readJson(all / "batch.json");
  CHECK(plan.at("workers") == 2);
  REQUIRE(plan.at("shards").size() == 3);
  CHECK(plan.at("shards")[1].at("first_frame") == 60);
  CHECK(plan.at("shards")[1].at("last_frame") == 124);  // 5 frames into shard 2

  // Every frame once, at the one-process stamps; keyframes as accurate within 1 cm.
  CHECK(mapping::readTum(all / "trajectory.tum").size() == 180);
  CHECK(slurp(all / "ground_truth.tum") == slurp(dir / "one" / "ground_truth.tum"));
  const double ate_batch = keyframeAte(all);
  CHECK(ate_batch < ate_one + 0.01);
  CHECK(ate_batch < 0.05);
  const auto summary = readJson(all / "summary.json");
  const auto& actors = summary.at("actors");
  CHECK(actors.at("stitcher").at("join_frames") == "60,120");
  CHECK(actors.at("graph").at("graph_keyframes") == actors.at("stitcher").at("keyframes"));
  CHECK(fs::file_size(all / "map.bt") > 0);
  CHECK(fs::file_size(all / "cloud.pcd") > 0);

  // As three hosts would: each map task alone, then the reduce alone.
  const fs::path split = dir / "split";
  for (int k = 0; k < 3; ++k) {
    const auto task = test::runCli("batch rgbd_slam --shards 3 --shard " + std::to_string(k) +
                                       " --out " + split.string() + sets,
                                   dir);
    INFO(task.err);
    REQUIRE(task.exit_code == 0);
  }
  const auto reduce =
      test::runCli("batch rgbd_slam --shards 3 --reduce --out " + split.string() + sets, dir);
  INFO(reduce.err);
  REQUIRE(reduce.exit_code == 0);
  CHECK(slurp(split / "keyframes.tum") == slurp(all / "keyframes.tum"));
  fs::remove_all(dir);
}

TEST_CASE("tessera batch refuses a profile, a plan or a reduce it cannot run", "[e2e][batch]") {
  const fs::path dir = test::scratchDir("e2e_batch_bad");
  const auto laser = test::runCli("batch sim_slam --out " + (dir / "a").string(), dir);
  CHECK(laser.exit_code != 0);
  CHECK_THAT(laser.err, Catch::Contains("0 rgbd_player and 0 rgbd_front_end"));

  const auto reduce =
      test::runCli("batch rgbd_slam --shards 2 --reduce --out " + (dir / "b").string(), dir);
  CHECK(reduce.exit_code != 0);
  CHECK_THAT(reduce.err, Catch::Contains("shard_0/shard.trec is missing") &&
                             Catch::Contains("--shard 0 --shards 2"));

  const auto shard =
      test::runCli("batch rgbd_slam --shards 2 --shard 2 --out " + (dir / "c").string(), dir);
  CHECK(shard.exit_code != 0);
  CHECK_THAT(shard.err, Catch::Contains("--shard 2 with --shards 2"));

  TESSERA_SHARED_DATA(tum, "tum-rgbd-fr1-desk-9frames");
  const auto many = test::runCli("batch rgbd_slam --shards 5 --out " + (dir / "d").string() +
                                     " --set player.path=" + tum.string(),
                                 dir);
  CHECK(many.exit_code != 0);
  CHECK_THAT(many.err, Catch::Contains("5 shards over 9 frames"));
  fs::remove_all(dir);
}
