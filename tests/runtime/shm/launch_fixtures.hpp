// What the deployment tests (launch_test.cpp through the CLI, launcher_test.cpp through the
// Launcher) share: fresh folders, file contents, the check that no shared memory is left, and a
// small wall-clock profile.
#pragma once

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace tessera::test {

/// An empty folder under the system's temporary directory.
inline std::filesystem::path freshDir(const std::string& name) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("tessera_test_" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

inline std::string readFile(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// True when neither RouDi's shared memory nor a launcher's control block is left in /dev/shm.
inline bool shmClean() {
  for (const auto& e : std::filesystem::directory_iterator("/dev/shm")) {
    const auto name = e.path().filename().string();
    if (name == "iceoryx_mgmt" || name.rfind("tessera_sync_", 0) == 0) return false;
  }
  return true;
}

/// Wall clock: the robot streams in real time, the mapper is fed by whichever robot is alive.
/// `restart` is the profile's restart line ("restart: [robot]") or "".
inline std::string wallMappingProfile(const std::string& restart) {
  return "name: wall_mapping\nclock: wall\n" + restart + R"(
actors:
  sim:
    type: simulator
    process: robot
    params: {world: builtin:office, laps: 1, scan_hz: 10, odom_hz: 50}
  mapper:
    type: grid_mapper
    process: mapping
    remap: {pose: ground_truth}
  map_writer:
    type: map_writer
    process: mapping
)";
}

}  // namespace tessera::test
