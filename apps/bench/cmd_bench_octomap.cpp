// `tessera bench octomap`: OctoMap insertion rate from RGB-D keyframe clouds (7-Scenes or TUM
// folder, ground-truth poses). For each variant a fresh map receives the same keyframes; the
// timed part is OctoMapBuilder::insert (any downsampling before insertion included); decoding and
// back-projection are not timed. Rate = points of the input cloud per second of insertion. The
// variants are octomap's three insertion paths (docs/algorithms.md#rgb-d-maps) on whole frames,
// the same with a voxel filter at the map resolution first, and the clouds the map keeps.
#include "bench_commands.hpp"
#include "bench_util.hpp"

#include <tessera/datasets/rgbd_sequence.hpp>
#include <tessera/mapping3d/octomap_builder.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>

#include <nlohmann/json.hpp>

#include <chrono>
#include <iomanip>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

namespace tessera::app {
namespace {

namespace m3 = tessera::mapping3d;

struct Options {
  std::string path = "../shared/data/7scenes-redkitchen-rgbd";
  int keyframes = 10;
  int step = 45;  // frames between keyframes
  double resolution = 0.05;
  double max_range = 4.0;
  bool json = false;
};

struct Variant {
  std::string name;
  m3::KeyframeCloudOptions cloud;
  m3::InsertMethod method = m3::InsertMethod::kPointCloud;
  double downsample = 0;  // [m], 0 = off
  bool lazy = false;      // octomap's per-voxel inner-node updates unless set
};

std::vector<Variant> variants(double resolution) {
  m3::KeyframeCloudOptions full;
  full.stride = 1;
  full.voxel_leaf = 0;
  m3::KeyframeCloudOptions kept;  // what the cloud map keeps per keyframe (defaults)
  return {
      {"pointcloud", full, m3::InsertMethod::kPointCloud, 0},
      {"discretized", full, m3::InsertMethod::kDiscretized, 0},
      {"rays", full, m3::InsertMethod::kRays, 0},
      {"pointcloud+voxel", full, m3::InsertMethod::kPointCloud, resolution},
      {"discretized+voxel", full, m3::InsertMethod::kDiscretized, resolution},
      {"discretized+lazy", full, m3::InsertMethod::kDiscretized, 0, true},
      {"keyframe_cloud+discretized", kept, m3::InsertMethod::kDiscretized, 0},
  };
}

struct Frame {
  datasets::RgbdImages images;
  Eigen::Isometry3d pose;
};

}  // namespace

void addBenchOctomapCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "octomap",
      "OctoMap insertion rate (points/s) and map memory from RGB-D keyframe clouds, octomap's "
      "insertion paths with and without downsampling");
  auto o = std::make_shared<Options>();
  cmd->add_option("--path", o->path, "dataset folder (7-Scenes or TUM layout)")
      ->capture_default_str();
  cmd->add_option("--keyframes", o->keyframes, "keyframes inserted")->capture_default_str();
  cmd->add_option("--step", o->step, "frames between keyframes")->capture_default_str();
  cmd->add_option("--resolution", o->resolution, "leaf voxel [m]")->capture_default_str();
  cmd->add_option("--max-range", o->max_range, "ray cut [m]; <= 0 none")->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    if (o->keyframes < 1) throw ConfigError("--keyframes must be >= 1");
    if (o->step < 1) throw ConfigError("--step must be >= 1");
    const auto sequence = datasets::readRgbdSequence(o->path);
    visual_slam::PinholeCamera camera;
    camera.fx = sequence.intrinsics.fx;
    camera.fy = sequence.intrinsics.fy;
    camera.cx = sequence.intrinsics.cx;
    camera.cy = sequence.intrinsics.cy;
    camera.width = sequence.intrinsics.width;
    camera.height = sequence.intrinsics.height;
    std::vector<Frame> frames;
    for (std::size_t i = 0; i < sequence.frames.size() && frames.size() < std::size_t(o->keyframes);
         i += static_cast<std::size_t>(o->step)) {
      if (!sequence.frames[i].pose) continue;
      frames.push_back({datasets::loadRgbdImages(sequence, i), *sequence.frames[i].pose});
    }
    if (frames.empty()) throw ConfigError("bench octomap: no frame with a pose in " + o->path);

    nlohmann::json results = nlohmann::json::array();
    for (const auto& v : variants(o->resolution)) {
      if (!o->json) std::cerr << "[bench octomap] " << v.name << " ...\n";
      m3::OctoMapOptions options;
      options.resolution = o->resolution;
      options.max_range = o->max_range;
      options.method = v.method;
      options.downsample_leaf = v.downsample;
      options.lazy_eval = v.lazy;
      m3::OctoMapBuilder map(options);
      std::size_t points = 0;
      double seconds = 0;
      std::vector<double> ms;
      for (const auto& f : frames) {
        visual_slam::RgbdFrame frame;
        frame.depth = cv::Mat(f.images.height, f.images.width, CV_16UC1,
                              const_cast<std::uint16_t*>(f.images.depth.data()));
        frame.depth_scale = f.images.depth_scale;
        const auto cloud = m3::makeKeyframeCloud(camera, frame, v.cloud);
        const auto start = std::chrono::steady_clock::now();
        map.insert(cloud, f.pose);
        const double s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        seconds += s;
        ms.push_back(1e3 * s);
        points += cloud.size();
      }
      const auto stats = map.stats();
      double mean_ms = 0;
      for (double x : ms) mean_ms += x / static_cast<double>(ms.size());
      results.push_back({{"variant", v.name},
                         {"method", m3::methodName(v.method)},
                         {"downsample_m", v.downsample},
                         {"lazy_eval", v.lazy},
                         {"stride", v.cloud.stride},
                         {"cloud_voxel_m", v.cloud.voxel_leaf},
                         {"keyframes", frames.size()},
                         {"points_in", points},
                         {"points_to_octomap", stats.points_inserted},
                         {"points_per_s", static_cast<double>(points) / seconds},
                         {"ms_per_cloud_mean", mean_ms},
                         {"ms_per_cloud_p95", percentile(ms, 0.95)},
                         {"leaves", stats.leaves},
                         {"occupied_leaves", stats.occupied_leaves},
                         {"memory_bytes", stats.memory_bytes}});
    }
    const nlohmann::json setup{{"sequence", o->path},
                               {"resolution_m", o->resolution},
                               {"max_range_m", o->max_range},
                               {"frame_step", o->step}};
    if (o->json) {
      std::cout << nlohmann::json{{"machine", machineDescription()},
                                  {"setup", setup},
                                  {"results", results}}
                       .dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << "sequence: " << o->path << ", " << frames.size() << " keyframes every " << o->step
              << " frames; resolution " << o->resolution << " m, max range " << o->max_range
              << " m\n\n"
              << std::left << std::setw(28) << "variant" << std::right << std::setw(10)
              << "pts/cloud" << std::setw(10) << "to tree" << std::setw(12) << "M points/s"
              << std::setw(10) << "ms mean" << std::setw(10) << "ms p95" << std::setw(10)
              << "leaves" << std::setw(10) << "MiB\n";
    for (const auto& r : results) {
      const double n = static_cast<double>(r["keyframes"].get<std::size_t>());
      std::cout << std::left << std::setw(28) << r["variant"].get<std::string>() << std::right
                << std::fixed << std::setprecision(0) << std::setw(10)
                << static_cast<double>(r["points_in"].get<std::size_t>()) / n << std::setw(10)
                << static_cast<double>(r["points_to_octomap"].get<std::size_t>()) / n
                << std::setprecision(2) << std::setw(12) << r["points_per_s"].get<double>() / 1e6
                << std::setprecision(1) << std::setw(10) << r["ms_per_cloud_mean"].get<double>()
                << std::setw(10) << r["ms_per_cloud_p95"].get<double>() << std::setw(10)
                << r["leaves"].get<std::size_t>() << std::setprecision(2) << std::setw(9)
                << static_cast<double>(r["memory_bytes"].get<std::size_t>()) / (1024.0 * 1024.0)
                << "\n";
    }
    result = 0;
  });
}

}  // namespace tessera::app
