// `tessera map export`: a saved laser SLAM state (tessera/laser_slam/slam_state.hpp) drawn into
// one occupancy map and written as PGM + YAML (map_server format, mapping::saveMap), the files
// monte_carlo_localizer and navigator load for runs without SLAM.
#include "commands.hpp"

#include <tessera/laser_slam/slam_state.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/runtime/options.hpp>

#include <array>
#include <charconv>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <memory>

namespace tessera::app {

namespace {

/// Submap resolutions come from Float32 message fields (0.05f = 0.0500000007 m). The live run's
/// map_writer writes such a value as the float it was meant to be (0.05); so does the export, so
/// that its YAML matches the run's map.yaml. Other values are kept as they are.
double intendedResolution(double r) {
  const auto f = static_cast<float>(r);
  if (static_cast<double>(f) != r) return r;
  std::array<char, 32> buf{};
  const auto end = std::to_chars(buf.data(), buf.data() + buf.size(), f).ptr;
  double d = r;
  std::from_chars(buf.data(), end, d);
  return d;
}

struct ExportOptions {
  std::string state;
  std::string out;
  double resolution = 0.0;
  bool png = true;
};

void addExport(CLI::App& map, int& result) {
  auto* cmd = map.add_subcommand(
      "export",
      "draw a saved SLAM state's submaps at their saved poses into one map and write it as "
      "PGM + YAML (+ PNG) for localisation-only runs");
  auto o = std::make_shared<ExportOptions>();
  cmd->add_option("state", o->state,
                  "SLAM state directory (state.yaml + cell files; map_assembler's state_dir, "
                  "e.g. OUT/slam_state)")
      ->required();
  cmd->add_option("--out", o->out,
                  "map base path: writes BASE.pgm, BASE.yaml and BASE.png (e.g. maps/office)")
      ->required();
  cmd->add_option("--resolution", o->resolution,
                  "cell size of the map [m]; 0 = the finest submap's")
      ->capture_default_str();
  cmd->add_flag("!--no-png", o->png, "do not write BASE.png");
  cmd->callback([o, &result] {
    if (!(std::isfinite(o->resolution) && o->resolution >= 0))
      throw ConfigError("--resolution must be >= 0 [m] (0 = the submaps')");
    const laser_slam::SlamState state = laser_slam::loadSlamState(o->state);
    if (state.submaps.empty())
      throw std::runtime_error(o->state + ": holds no submaps, nothing to export");
    grid::OccupancyMap map = laser_slam::assembleSlamState(state, o->resolution);
    map.resolution = intendedResolution(map.resolution);
    mapping::MapSaveOptions save;
    save.write_png = o->png;
    const mapping::SavedMap saved = mapping::saveMap(map, o->out, save);
    std::cout << "exported " << state.submaps.size() << " submaps (" << state.constraints.size()
              << " constraints, " << state.cameras.size() << " calibrated cameras) from "
              << o->state << "\n"
              << "map: " << map.width << " x " << map.height << " cells at " << map.resolution
              << " m, origin (" << std::setprecision(6) << map.origin.x << ", " << map.origin.y
              << ") m in frame " << state.frame_id << "\n"
              << "wrote " << saved.yaml.string() << ", " << saved.pgm.string()
              << (saved.png.empty() ? "" : ", " + saved.png.string()) << "\n";
    result = 0;
  });
}

}  // namespace

void addMapCommand(CLI::App& app, int& result) {
  auto* map = app.add_subcommand("map", "saved SLAM maps (map_assembler's state_dir)");
  map->require_subcommand(1);
  addExport(*map, result);
}

}  // namespace tessera::app
