// What the simulator actors share when they check their options (private to tessera_sim_actors):
// errors that name the actor and the full dotted option key, loading the world, the route to
// drive (given or the world's own) and the seeded noise streams.
#pragma once

#include <tessera/runtime/options.hpp>
#include <tessera/sim/config_check.hpp>
#include <tessera/sim/world.hpp>

#include <array>
#include <cstdint>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace tessera::sim::detail {

/// Throws ConfigError "ACTOR: option 'KEY': WHAT".
class OptionErrors {
 public:
  explicit constexpr OptionErrors(const char* actor) : actor_(actor) {}

  [[noreturn]] void fail(const std::string& key, const std::string& what) const;
  /// Fails with the first problem a check found, its key prefixed "`group`." (none for "").
  void check(const ConfigCheck& check, const std::string& group = "") const;

  /// World::fromSpec; a bad resolution fails as `world_resolution`, anything else as `world`.
  World loadWorld(const std::string& spec, double resolution) const;
  /// The given waypoints, or the world's default route when none are given.
  Route routeOrDefault(const World& world, const std::vector<std::array<double, 2>>& given) const;

 private:
  const char* actor_;
};

/// Noise streams: each sensor draws from its own, so that changing one (a laser's beam count,
/// say) does not shift the noise of another in a run with the same seed.
enum class NoiseStream : std::uint32_t {
  kLaser = 0x6c617372u,           // "lasr"
  kLandmarkSensor = 0x6c6d6b73u,  // "lmks"
  kCameras = 0x63616d73u,         // "cams"
  kCameraImages = 0x63696d67u,    // "cimg"
  kRgbdCamera = 0x72676264u,      // "rgbd"
  kGyro = 0x6779726fu,            // "gyro"
  kEncoders = 0x656e6373u,        // "encs"
};
std::mt19937_64 seededStream(std::uint64_t seed, NoiseStream stream);

template <typename T>
std::string str(const T& v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

}  // namespace tessera::sim::detail
