#include <tessera/datasets/rgbd_sequence.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/players/rgbd_player.hpp>
#include <tessera/runtime/harness.hpp>
#include <tessera/runtime/registry.hpp>

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstring>
#include <fstream>

#include "../../shared_data.hpp"

using namespace tessera;
using tessera::players::RgbdPlayerActor;
using tessera::players::RgbdPlayerOptions;
namespace fs = std::filesystem;

namespace {

constexpr const char* kTum = "tum-rgbd-fr1-desk-9frames";
constexpr const char* kSeven = "7scenes-redkitchen-rgbd";

// Advances in 100 ms slices until the player stops publishing (or `limit_s`).
void runToEnd(ActorHarness& h, double limit_s) {
  for (double t = 0; t < limit_s; t += 0.1) {
    const std::size_t before = h.publishedCount("rgbd");
    h.advance(kNanosPerSecond / 10);
    if (h.publishedCount("rgbd") == before && t > 1.0) return;
  }
}

std::string configErrorOf(const RgbdPlayerOptions& o) {
  try {
    RgbdPlayerActor a(o);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

std::int64_t summaryInt(const Summary& s, const std::string& key) {
  return std::get<std::int64_t>(s.at(key));
}

}  // namespace

TEST_CASE("rgbd_player replays TUM fr1/desk at its own timestamps with ground truth",
          "[players][rgbd]") {
  TESSERA_SHARED_DATA(dir, kTum);
  RgbdPlayerOptions o;
  o.path = dir.string();
  ActorHarness h(std::make_unique<RgbdPlayerActor>(o));
  const auto& seq = static_cast<RgbdPlayerActor&>(h.actor()).sequence();
  runToEnd(h, 5);

  const auto frames = h.published<msg::RgbdFrame>("rgbd");
  const auto gt = h.published<msg::GroundTruthPose3D>("ground_truth");
  const auto gt2 = h.published<msg::GroundTruthPose>("ground_truth_2d");
  REQUIRE(frames.size() == 9);
  REQUIRE(gt.size() == 9);
  REQUIRE(gt2.size() == 9);
  const datasets::RgbdImages first = datasets::loadRgbdImages(seq, 0);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    INFO("frame " << i);
    const auto f = *frames[i];
    const double dt = seq.frames[i].timestamp - seq.frames[0].timestamp;
    CHECK(f.getHeader().getStampNs() == std::llround(dt * 1e9));
    CHECK(f.getHeader().getSeq() == i);
    CHECK(std::string(f.getHeader().getFrameId().cStr()) == "camera");
    CHECK(f.getDatasetTimeS() == seq.frames[i].timestamp);
    CHECK(std::abs(f.getDepthTimeOffsetS()) < 0.02);
    CHECK(f.getDepthScale() == 5000);
    CHECK(f.getColorRegistered());
    CHECK(f.getIntrinsics().getFx() == 517.3);
    CHECK(f.getIntrinsics().getDistortion().size() == 5);
    CHECK(std::string(f.getColor().getEncoding().cStr()) == "rgb8");
    CHECK(std::string(f.getDepth().getEncoding().cStr()) == "16UC1");
    CHECK(f.getColor().getStep() == 640 * 3);
    CHECK(f.getDepth().getStep() == 640 * 2);
    CHECK(f.getColor().getData().size() == 640u * 480u * 3u);
    CHECK(f.getDepth().getData().size() == 640u * 480u * 2u);
    REQUIRE(f.getHasGroundTruth());
    const Eigen::Vector3d t = seq.frames[i].pose->translation();
    CHECK(f.getGroundTruth().getX() == t.x());
    CHECK(gt[i]->getPose().getZ() == t.z());
    CHECK(gt[i]->getHeader().getStampNs() == f.getHeader().getStampNs());
    CHECK(std::string(gt[i]->getHeader().getFrameId().cStr()) == "world");
    const Eigen::Quaterniond q(gt[i]->getPose().getQw(), gt[i]->getPose().getQx(),
                               gt[i]->getPose().getQy(), gt[i]->getPose().getQz());
    CHECK(q.norm() == Approx(1.0));
    CHECK(q.angularDistance(Eigen::Quaterniond(seq.frames[i].pose->rotation())) < 1e-9);
    const Eigen::Vector3d axis = seq.frames[i].pose->rotation().col(2);
    CHECK(gt2[i]->getPose().getX() == t.x());
    CHECK(gt2[i]->getPose().getTheta() == Approx(std::atan2(axis.y(), axis.x())));
  }
  // The first frame's pixels are the loader's, byte for byte.
  const auto c = frames[0]->getColor().getData();
  const auto d = frames[0]->getDepth().getData();
  CHECK(std::memcmp(c.begin(), first.color.data(), c.size()) == 0);
  CHECK(std::memcmp(d.begin(), first.depth.data(), d.size()) == 0);

  Summary s;
  h.actor().summarize(s);
  CHECK(summaryInt(s, "frames_published") == 9);
  CHECK(summaryInt(s, "ground_truth_published") == 9);
  CHECK(std::get<double>(s.at("load_ms_mean")) > 0);
  CHECK(h.runtime().report().stop_reason.empty());
}

TEST_CASE("rgbd_player plays a 7-Scenes frame range at 30 Hz with float depth", "[players][rgbd]") {
  TESSERA_SHARED_DATA(dir, kSeven);
  RgbdPlayerOptions o;
  o.path = dir.string();
  o.layout = "7scenes";
  o.first_frame = 100;
  o.last_frame = 111;
  o.depth = "float";
  o.rate = 2.0;
  ActorHarness h(std::make_unique<RgbdPlayerActor>(o));
  runToEnd(h, 5);
  const auto frames = h.published<msg::RgbdFrame>("rgbd");
  REQUIRE(frames.size() == 12);
  CHECK(h.publishedCount("ground_truth") == 12);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const auto f = *frames[i];
    CHECK(f.getFrameIndex() == 100 + i);
    // 30 Hz played at rate 2: 1/60 s apart.
    CHECK(f.getHeader().getStampNs() == std::llround(static_cast<double>(i) / 60.0 * 1e9));
    CHECK(f.getDatasetTimeS() == Approx((100.0 + static_cast<double>(i)) / 30.0));
    CHECK_FALSE(f.getColorRegistered());
    CHECK(f.getDepthScale() == 1.0);
    CHECK(f.getIntrinsics().getFx() == 585);
    CHECK(std::string(f.getDepth().getEncoding().cStr()) == "32FC1");
    const auto bytes = f.getDepth().getData();
    REQUIRE(bytes.size() == 640u * 480u * 4u);
    std::vector<float> metres(640 * 480);
    std::memcpy(metres.data(), bytes.begin(), bytes.size());
    std::size_t valid = 0, nan = 0;
    for (float m : metres) {
      if (std::isnan(m))
        ++nan;
      else if (m > 0.3f && m < 8.0f)
        ++valid;
    }
    CHECK(valid + nan == metres.size());  // every pixel is a plausible depth or "no reading"
    CHECK(valid > metres.size() / 2);
  }
}

TEST_CASE("rgbd_player rejects bad options naming the option", "[players][rgbd]") {
  RgbdPlayerOptions o;
  CHECK_THAT(configErrorOf(o), Catch::Contains("'path'") && Catch::Contains("required"));
  o.path = "/nonexistent/folder";
  CHECK_THAT(configErrorOf(o), Catch::Contains("'path'") && Catch::Contains("not a folder"));
  TESSERA_SHARED_DATA(dir, kTum);
  o.path = dir.string();
  CHECK(configErrorOf(o).empty());
  auto with = [&](auto change) {
    RgbdPlayerOptions c = o;
    change(c);
    return configErrorOf(c);
  };
  CHECK_THAT(with([](auto& c) { c.layout = "kitti"; }), Catch::Contains("'layout'"));
  CHECK_THAT(with([](auto& c) { c.layout = "7scenes"; }), Catch::Contains("depth.png"));
  CHECK_THAT(with([](auto& c) { c.rate = 0; }), Catch::Contains("'rate'"));
  CHECK_THAT(with([](auto& c) { c.rate = NAN; }), Catch::Contains("'rate'"));
  CHECK_THAT(with([](auto& c) { c.depth = "mm"; }), Catch::Contains("'depth'"));
  CHECK_THAT(with([](auto& c) { c.first_frame = 9; }), Catch::Contains("'first_frame'"));
  CHECK_THAT(with([](auto& c) { c.first_frame = -1; }), Catch::Contains("'first_frame'"));
  CHECK_THAT(with([](auto& c) { c.last_frame = 9; }), Catch::Contains("'last_frame'"));
  CHECK_THAT(with([](auto& c) {
               c.first_frame = 5;
               c.last_frame = 4;
             }),
             Catch::Contains("'last_frame'"));
  CHECK_THAT(with([](auto& c) { c.camera = "freiburg9"; }), Catch::Contains("freiburg9"));
  CHECK_THAT(with([](auto& c) { c.max_time_difference = -1; }),
             Catch::Contains("max_time_difference"));

  // Through the registry and YAML, as a profile would create it.
  const auto* entry = ActorRegistry::instance().find("rgbd_player");
  REQUIRE(entry != nullptr);
  CHECK(entry->options().size() == 12);
  CHECK_THROWS_AS(ActorRegistry::instance().create(
                      "rgbd_player", Params(YAML::Load("{path: x, speed: 2}"), "test")),
                  ConfigError);
}

TEST_CASE("rgbd_player stops the run naming the file when an image is corrupt", "[players][rgbd]") {
  TESSERA_SHARED_DATA(src, kTum);
  const fs::path dir = tessera::test::scratchDir("rgbd_player_corrupt") / "tum-fr1";
  fs::create_directories(dir / "rgb");
  fs::create_directories(dir / "depth");
  for (const char* f : {"rgb.txt", "depth.txt", "groundtruth.txt"}) fs::copy_file(src / f, dir / f);
  for (const char* sub : {"rgb", "depth"})
    for (const auto& e : fs::directory_iterator(src / sub))
      fs::copy_file(e.path(), dir / sub / e.path().filename());
  // Frame 3's depth image loses its second half.
  const fs::path victim = dir / "depth" / "1305031453.473352.png";
  std::string bytes;
  {
    std::ifstream in(victim, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  std::ofstream(victim, std::ios::binary | std::ios::trunc) << bytes.substr(0, bytes.size() / 2);

  RgbdPlayerOptions o;
  o.path = dir.string();
  ActorHarness h(std::make_unique<RgbdPlayerActor>(o));
  runToEnd(h, 3);
  CHECK(h.publishedCount("rgbd") == 3);
  const RunReport report = h.runtime().report();
  CHECK(report.interrupted);
  CHECK_THAT(report.stop_reason, Catch::Contains("frame 3") &&
                                     Catch::Contains("1305031453.473352.png") &&
                                     Catch::Contains("truncated PNG"));
  Summary s;
  h.actor().summarize(s);
  CHECK_THAT(std::get<std::string>(s.at("error")), Catch::Contains("1305031453.473352.png"));
}
