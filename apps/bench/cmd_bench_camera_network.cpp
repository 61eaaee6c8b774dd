// `tessera bench camera_network`: the seed-000 paper's experiment on the simulated camera floor
// (docs/benchmarks.md). Four laser SLAM configurations, each with and without the cameras:
//   scan_matching    one particle: incremental scan matching (Vasco-like);
//   rbpf50           one RBPF with 50 particles (GMapping-like);
//   two_level_sgd    RBPF submaps of 10 particles, loop detector, SGD graph;
//   two_level_ceres  the same with Ceres, and the profile's scan-level graph at the end (if on;
//                    a Ceres problem, so the other configurations leave it off).
// two_level_ceres keeps the profile's map drawn from the scans at the end (map.pgm, the submaps
// in map_submaps.pgm); the others' map is the submap mosaic.
// Without cameras the first two build one map and the two-level ones cut a submap every
// --submap-distance metres; with cameras every configuration cuts a submap on entering a camera,
// and the cameras calibrate themselves and add revisit constraints (SGD graph for the first two).
// Each run is a profile derived from sim_camera_slam, run as its own `tessera run` child process
// (peak RSS and CPU are that run's). A run is repeatable (simulated clock), but one seed is one
// draw of the noise: --seeds runs each configuration once per seed (simulator, cameras and
// filter), and a configuration's figures are then the mean over seeds (CPU, RSS, submaps and
// constraints: the median). Scored: ATE of trajectory_final.tum against the truth, the
// map against the world's true walls moved by the same rigid alignment
// (evaluation/map_metrics.hpp), and the cameras' figures.
#include "bench_commands.hpp"
#include "bench_util.hpp"
#include "child_process.hpp"
#include "cli_inputs.hpp"

#include <tessera/evaluation/map_metrics.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/io/image_file.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/profile.hpp>

#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <set>
#include <sstream>

namespace tessera::app {
namespace {

namespace fs = std::filesystem;

struct Options {
  std::string profile = "sim_camera_slam";
  std::vector<std::string> configurations{"scan_matching", "rbpf50", "two_level_sgd",
                                          "two_level_ceres"};
  std::string cameras = "both";
  std::vector<int> seeds{1};
  double max_duration_s = 0;
  double submap_distance = 30;
  std::string out = "out/bench_camera_network";
  std::string montage = "maps.png";
  bool json = false;
};

const std::set<std::string> kConfigurations = {"scan_matching", "rbpf50", "two_level_sgd",
                                               "two_level_ceres"};

/// The profile of one run: sim_camera_slam changed as the configuration says.
YAML::Node deriveProfile(YAML::Node base, const std::string& config, bool cameras, int seed,
                         const Options& o) {
  YAML::Node p = YAML::Clone(base);
  p["name"] = "bench_" + config + (cameras ? "_cameras" : "");
  if (o.max_duration_s > 0) p["max_duration_s"] = o.max_duration_s;
  YAML::Node actors = p["actors"];
  for (const char* needed : {"slam", "camera_slam", "loops", "optimizer"})
    if (!actors[needed])
      throw ConfigError("bench camera_network: profile " + o.profile + " has no actor '" + needed +
                        "'");
  YAML::Node slam = actors["slam"]["params"];
  slam["rbpf"]["seed"] = seed;
  for (const char* noisy : {"sim", "cameras"})
    if (actors[noisy]) actors[noisy]["params"]["seed"] = seed;
  const bool two_level = config == "two_level_sgd" || config == "two_level_ceres";
  slam["rbpf"]["particles"] = config == "scan_matching" ? 1 : config == "rbpf50" ? 50 : 10;
  slam["camera_trigger"] = cameras;
  slam["submap_distance"] = (!cameras && two_level) ? o.submap_distance : 0.0;
  if (!cameras) actors.remove("camera_slam");
  if (!two_level) actors.remove("loops");
  actors["optimizer"]["params"]["graph"]["optimizer"]["solver"] =
      config == "two_level_ceres" ? "ceres" : "sgd";
  // The scan-level graph of the final optimisation is solved by Ceres: the others stay SGD only.
  // The map drawn from the scans needs that graph's trajectory (with the submaps' smoothed
  // poses alone it draws what the submaps drew, less well): the others score the submap mosaic.
  if (config != "two_level_ceres") {
    actors["optimizer"]["params"]["scan_graph"]["enabled"] = false;
    if (actors["final_mapper"]) {
      actors.remove("final_mapper");
      actors.remove("submap_map_writer");
      actors["map_writer"].remove("remap");
    }
  }
  // The true walls, for the map score.
  YAML::Node walls;
  walls["type"] = "world_writer";
  walls["params"]["world"] = "builtin:camera_floor";
  walls["params"]["walls_file"] = "walls.txt";
  actors["true_walls"] = walls;
  return p;
}

double value(const nlohmann::json& j, const char* key) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : 0.0;
}

/// A figure an actor reports only when it measured it: null otherwise.
nlohmann::json optional(const nlohmann::json& j, const char* key) {
  return j.contains(key) && j[key].is_number() ? j[key] : nlohmann::json(nullptr);
}

/// The keys of one configuration in the --json output (the shape, nothing more).
const char* const kJsonKeys[] = {
    "name",        "cameras", "ate_rmse_m", "max_error_m", "wall_cells_found", "false_wall_cells",
    "peak_rss_mb", "cpu_s",   "submaps",    "constraints"};

nlohmann::json scoreRun(const fs::path& dir, const std::string& config, bool cameras) {
  nlohmann::json summary;
  std::ifstream(dir / "summary.json") >> summary;
  const nlohmann::json actors = summary.value("actors", nlohmann::json::object());
  const auto truth = mapping::readTum(dir / "ground_truth.tum");
  const auto ate = evaluation::computeAte(mapping::readTum(dir / "trajectory_final.tum"), truth);
  // The walls move into the SLAM's map frame by the trajectory's rigid alignment (the map's
  // placement in the world is a free choice, as for the ATE).
  const auto toMap = [&](const Eigen::Vector2d& p) -> Eigen::Vector2d {
    return ate.alignment.unapply({p.x(), p.y(), 0}).head<2>();
  };
  auto walls = evaluation::readWalls((dir / "walls.txt").string());
  for (auto& w : walls) {
    w.a = toMap(w.a);
    w.b = toMap(w.b);
  }
  const auto map = evaluation::scoreMapAgainstWalls(mapping::loadMap(dir / "map.yaml"), walls);
  const nlohmann::json cams = actors.value("camera_slam", nlohmann::json::object());
  const nlohmann::json slam = actors.value("slam", nlohmann::json::object());
  const nlohmann::json optimizer = actors.value("optimizer", nlohmann::json::object());
  nlohmann::json row{{"name", config},
                     {"cameras", cameras},
                     {"ate_rmse_m", ate.translation.rmse},
                     {"max_error_m", ate.translation.max},
                     {"wall_cells_found", map.wall_cells_found},
                     {"false_wall_cells", map.false_wall_cells},
                     {"doubled_wall_cells", map.doubled_wall_cells},
                     {"displaced_wall_cells", map.displaced_wall_cells},
                     {"peak_rss_mb", value(summary, "peak_rss_mb")},
                     {"cpu_s", value(summary, "cpu_s")},
                     {"submaps", static_cast<int>(value(slam, "submaps"))},
                     {"constraints", static_cast<int>(value(optimizer, "graph_edges"))},
                     {"out", dir.string()}};
  if (cameras) {
    row["camera_calibrations"] = static_cast<int>(value(cams, "calibrations"));
    row["calibration_rms_px"] = optional(cams, "calibration_rms_px");
    row["camera_localisation_error_m"] = optional(cams, "camera_localisation_rms_m");
    row["revisits"] = static_cast<int>(value(cams, "revisits"));
    row["false_revisit_constraints"] = static_cast<int>(value(cams, "revisits_false"));
    row["revisit_nees"] = optional(cams, "revisit_nees");
  }
  return row;
}

/// One configuration's row from its runs over seeds: accuracy and map figures are the mean,
/// resources and counts the median, false revisits the sum; the maps are the first seed's.
nlohmann::json combineSeeds(const std::vector<nlohmann::json>& runs) {
  nlohmann::json row = runs.front();
  nlohmann::json ates = nlohmann::json::array();
  for (const auto& r : runs) ates.push_back(r["ate_rmse_m"]);
  row["ate_per_seed"] = ates;
  if (runs.size() == 1) return row;
  const auto numbers = [&](const char* key) {
    std::vector<double> v;
    for (const auto& r : runs)
      if (r.contains(key) && r[key].is_number()) v.push_back(r[key].get<double>());
    return v;
  };
  const auto mean = [&](const char* key) -> nlohmann::json {
    const auto v = numbers(key);
    if (v.empty()) return nullptr;
    double sum = 0;
    for (double x : v) sum += x;
    return sum / static_cast<double>(v.size());
  };
  for (const char* key : {"ate_rmse_m", "max_error_m", "wall_cells_found"}) row[key] = mean(key);
  for (const char* key : {"false_wall_cells", "doubled_wall_cells", "displaced_wall_cells"})
    row[key] = static_cast<std::size_t>(std::llround(mean(key).get<double>()));
  for (const char* key : {"peak_rss_mb", "cpu_s"}) row[key] = median(numbers(key));
  for (const char* key : {"submaps", "constraints"})
    row[key] = static_cast<int>(std::lround(median(numbers(key))));
  if (row["cameras"].get<bool>()) {
    for (const char* key : {"calibration_rms_px", "camera_localisation_error_m", "revisit_nees"})
      row[key] = mean(key);
    for (const char* key : {"camera_calibrations", "revisits"})
      row[key] = static_cast<int>(std::lround(median(numbers(key))));
    int false_revisits = 0;
    for (const auto& r : runs) false_revisits += r["false_revisit_constraints"].get<int>();
    row["false_revisit_constraints"] = false_revisits;
  }
  return row;
}

/// Every run's map.pgm in one PNG: a column per configuration, a row per camera mode, each tile
/// scaled to `tile_width` pixels and labelled.
void writeMontage(const nlohmann::json& rows, const fs::path& file, int tile_width = 640) {
  std::vector<std::string> configs;
  std::vector<bool> modes;
  for (const auto& r : rows) {
    const auto name = r["name"].get<std::string>();
    if (std::find(configs.begin(), configs.end(), name) == configs.end()) configs.push_back(name);
    const bool cams = r["cameras"].get<bool>();
    if (std::find(modes.begin(), modes.end(), cams) == modes.end()) modes.push_back(cams);
  }
  std::vector<cv::Mat> tiles(configs.size() * modes.size());
  int tile_height = 1;
  for (const auto& r : rows) {
    const auto g = io::readGray8(fs::path(r["out"].get<std::string>()) / "map.pgm");
    const cv::Mat map(g.height, g.width, CV_8UC1, const_cast<std::uint8_t*>(g.pixels.data()));
    cv::Mat tile;
    cv::resize(map, tile, cv::Size(tile_width, std::max(1, g.height * tile_width / g.width)), 0, 0,
               cv::INTER_AREA);
    const std::string label = r["name"].get<std::string>() +
                              (r["cameras"].get<bool>() ? " + cameras" : "") + "   ATE " +
                              std::to_string(r["ate_rmse_m"].get<double>()).substr(0, 5) + " m";
    cv::putText(tile, label, {8, 24}, cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(0), 2);
    const auto col = static_cast<std::size_t>(
        std::find(configs.begin(), configs.end(), r["name"].get<std::string>()) - configs.begin());
    const auto row = static_cast<std::size_t>(
        std::find(modes.begin(), modes.end(), r["cameras"].get<bool>()) - modes.begin());
    tile_height = std::max(tile_height, tile.rows);
    tiles[row * configs.size() + col] = tile;
  }
  cv::Mat out(tile_height * static_cast<int>(modes.size()),
              tile_width * static_cast<int>(configs.size()), CV_8UC1, cv::Scalar(205));
  for (std::size_t k = 0; k < tiles.size(); ++k) {
    if (tiles[k].empty()) continue;
    const int x = static_cast<int>(k % configs.size()) * tile_width;
    const int y = static_cast<int>(k / configs.size()) * tile_height;
    tiles[k].copyTo(out(cv::Rect(x, y, tiles[k].cols, tiles[k].rows)));
  }
  io::Gray8 image{out.cols, out.rows, std::vector<std::uint8_t>(out.datastart, out.dataend)};
  io::writePngGray8(image, file);
}

}  // namespace

void addBenchCameraNetworkCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "camera_network",
      "seed 000's experiment on the simulated camera floor: scan matching, RBPF with 50 "
      "particles and two-level SLAM (SGD, Ceres), each with and without the cameras");
  auto o = std::make_shared<Options>();
  cmd->add_option("--profile", o->profile,
                  "base profile (needs actors slam, camera_slam, loops, "
                  "optimizer)")
      ->capture_default_str();
  cmd->add_option("--configurations", o->configurations,
                  "any of scan_matching, rbpf50, two_level_sgd, two_level_ceres")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--cameras", o->cameras, "both, on or off")->capture_default_str();
  cmd->add_option("--seeds", o->seeds,
                  "seeds of the simulator, the cameras and the filter; one run of each "
                  "configuration per seed, figures averaged (resources: median)")
      ->delimiter(',')
      ->check(CLI::Validator(
          [](std::string& v) {
            const bool digits = !v.empty() && v.size() <= 9 &&
                                v.find_first_not_of("0123456789") == std::string::npos;
            return digits ? std::string()
                          : "expected seeds as non-negative integers separated by commas, got '" +
                                v + "'";
          },
          "SEED[,SEED...]"))
      ->capture_default_str();
  cmd->add_option("--max-duration", o->max_duration_s,
                  "stop each run after this much simulated time [s]; 0 = the whole route")
      ->capture_default_str();
  cmd->add_option("--submap-distance", o->submap_distance,
                  "two-level runs without cameras: a new submap every this many metres")
      ->capture_default_str();
  cmd->add_option("--out", o->out, "output folder (one sub-folder per run)")->capture_default_str();
  cmd->add_option("--montage", o->montage,
                  "every run's map side by side in this PNG (relative to --out); empty = none")
      ->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    for (const auto& c : o->configurations)
      if (!kConfigurations.count(c))
        throw ConfigError("--configurations: unknown '" + c +
                          "' (scan_matching, rbpf50, two_level_sgd, two_level_ceres)");
    if (o->cameras != "both" && o->cameras != "on" && o->cameras != "off")
      throw ConfigError("--cameras must be both, on or off, got '" + o->cameras + "'");
    if (o->seeds.empty()) throw ConfigError("--seeds needs at least one value");
    if (!(o->max_duration_s >= 0) || !(o->submap_distance > 0))
      throw ConfigError("--max-duration must be >= 0 and --submap-distance > 0");
    const std::string path = resolveProfilePath(o->profile, profileSearchDirs());
    const YAML::Node base = YAML::LoadFile(path);
    std::vector<bool> camera_modes;
    if (o->cameras != "on") camera_modes.push_back(false);
    if (o->cameras != "off") camera_modes.push_back(true);

    std::vector<std::pair<std::string, bool>> runs_of;  // (configuration, cameras), in order
    for (const auto& config : o->configurations)
      for (bool cameras : camera_modes) runs_of.emplace_back(config, cameras);
    std::vector<std::vector<nlohmann::json>> runs(runs_of.size());
    const std::size_t total = runs_of.size() * o->seeds.size();
    std::size_t done = 0;
    // Seeds outermost: the configurations compared see the machine alike.
    for (const int seed : o->seeds)
      for (std::size_t k = 0; k < runs_of.size(); ++k) {
        const auto& [config, cameras] = runs_of[k];
        const std::string name = config + (cameras ? "_cameras" : "");
        const fs::path dir = o->seeds.size() > 1
                                 ? fs::path(o->out) / name / ("seed_" + std::to_string(seed))
                                 : fs::path(o->out) / name;
        fs::create_directories(dir);
        const fs::path profile = dir / "profile.yaml";
        {
          YAML::Emitter e;
          e << deriveProfile(base, config, cameras, seed, *o);
          std::ofstream(profile) << e.c_str() << "\n";
        }
        ++done;
        if (!o->json)
          std::cerr << "[bench camera_network] " << done << "/" << total << " " << name << " seed "
                    << seed << " ...\n";
        const int code =
            runTesseraChild({"tessera", "run", profile.string(), "--quiet", "--out", dir.string()},
                            dir / "run.log");
        if (code != 0)
          throw std::runtime_error("bench camera_network: run " + name + " failed (exit " +
                                   std::to_string(code) + "), see " + (dir / "run.log").string());
        runs[k].push_back(scoreRun(dir, config, cameras));
      }
    nlohmann::json rows = nlohmann::json::array();
    for (const auto& r : runs) rows.push_back(combineSeeds(r));

    if (!o->montage.empty()) writeMontage(rows, fs::path(o->out) / o->montage);

    // The cameras' own figures from two_level_ceres with cameras (the paper's method), else the
    // last run with cameras; false revisits summed over every run with cameras.
    nlohmann::json calibration = nullptr, localisation = nullptr;
    int false_revisits = 0;
    bool from_ceres = false;
    for (const auto& r : rows) {
      if (!r["cameras"].get<bool>()) continue;
      false_revisits += r["false_revisit_constraints"].get<int>();
      if (from_ceres) continue;
      calibration = r["calibration_rms_px"];
      localisation = r["camera_localisation_error_m"];
      from_ceres = r["name"] == "two_level_ceres";
    }
    if (o->json) {
      nlohmann::json configurations = nlohmann::json::array();
      for (const auto& r : rows) {
        nlohmann::json c = nlohmann::json::object();
        for (const char* key : kJsonKeys) c[key] = r[key];
        configurations.push_back(c);
      }
      std::cout << nlohmann::json{{"machine", machineDescription()},
                                  {"configurations", configurations},
                                  {"calibration_rms_px", calibration},
                                  {"camera_localisation_error_m", localisation},
                                  {"false_revisit_constraints", false_revisits}}
                       .dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << "seed 000 camera floor (" << o->profile
              << "); ATE of trajectory_final.tum; walls found / false / doubled (a wall drawn "
                 "twice) / displaced (drawn once, beside its place) against the true walls\n\n"
              << std::left << std::setw(17) << "configuration" << std::setw(9) << "cameras"
              << std::right << std::setw(8) << "ATE m" << std::setw(8) << "max m" << std::setw(8)
              << "walls" << std::setw(8) << "false" << std::setw(9) << "doubled" << std::setw(8)
              << "displ." << std::setw(9) << "RSS MB" << std::setw(8) << "CPU s" << std::setw(9)
              << "submaps" << std::setw(8) << "edges\n";
    for (const auto& r : rows) {
      std::cout << std::left << std::setw(17) << r["name"].get<std::string>() << std::setw(9)
                << (r["cameras"].get<bool>() ? "yes" : "no") << std::right << std::fixed
                << std::setprecision(3) << std::setw(8) << r["ate_rmse_m"].get<double>()
                << std::setw(8) << r["max_error_m"].get<double>() << std::setw(8)
                << r["wall_cells_found"].get<double>() << std::setw(8)
                << r["false_wall_cells"].get<std::size_t>() << std::setw(9)
                << r["doubled_wall_cells"].get<std::size_t>() << std::setw(8)
                << r["displaced_wall_cells"].get<std::size_t>() << std::setprecision(1)
                << std::setw(9) << r["peak_rss_mb"].get<double>() << std::setw(8)
                << r["cpu_s"].get<double>() << std::setw(9) << r["submaps"].get<int>()
                << std::setw(8) << r["constraints"].get<int>() << "\n";
    }
    const auto figure = [](const nlohmann::json& v, int precision) {
      if (v.is_null()) return std::string("-");
      std::ostringstream s;
      s << std::fixed << std::setprecision(precision) << v.get<double>();
      return s.str();
    };
    if (o->seeds.size() > 1) {
      std::cout << "\nmeans over seeds";
      for (const int seed : o->seeds) std::cout << " " << seed;
      std::cout << " (CPU, RSS, submaps, edges: medians); ATE per seed:\n";
      for (const auto& r : rows) {
        std::cout << "  " << std::left << std::setw(17) << r["name"].get<std::string>()
                  << std::setw(9) << (r["cameras"].get<bool>() ? "yes" : "no") << std::right
                  << std::setprecision(3);
        for (const auto& a : r["ate_per_seed"]) std::cout << std::setw(8) << a.get<double>();
        std::cout << "\n";
      }
    }
    for (const auto& r : rows)
      if (r["cameras"].get<bool>())
        std::cout << "cameras in " << r["name"].get<std::string>() << ": "
                  << r["camera_calibrations"].get<int>() << " calibrated (RMS "
                  << figure(r["calibration_rms_px"], 2) << " px), localisation RMS "
                  << figure(r["camera_localisation_error_m"], 3) << " m, "
                  << r["revisits"].get<int>() << " revisit constraints, "
                  << r["false_revisit_constraints"].get<int>() << " false, NEES "
                  << figure(r["revisit_nees"], 1) << " (3 when consistent)\n";
    result = 0;
  });
}

}  // namespace tessera::app
