// Option errors, world loading, routes and noise streams shared by the simulator actors.
#include "option_checks.hpp"

#include <stdexcept>

namespace tessera::sim::detail {

void OptionErrors::fail(const std::string& key, const std::string& what) const {
  throw ConfigError(std::string(actor_) + ": option '" + key + "': " + what);
}

void OptionErrors::check(const ConfigCheck& check, const std::string& group) const {
  if (const auto& p = check.problem()) fail(group.empty() ? p->key : group + "." + p->key, p->what);
}

World OptionErrors::loadWorld(const std::string& spec, double resolution) const {
  try {
    return World::fromSpec(spec, resolution);
  } catch (const std::invalid_argument& e) {
    fail("world_resolution", e.what());
  } catch (const std::exception& e) {
    fail("world", e.what());
  }
}

Route OptionErrors::routeOrDefault(const World& world,
                                   const std::vector<std::array<double, 2>>& given) const {
  Route route;
  if (given.empty()) {
    route = world.defaultRoute();
    if (route.empty())
      fail("route", "world '" + world.name() + "' has no default route; give waypoints");
  } else {
    for (const auto& p : given) route.emplace_back(p[0], p[1]);
  }
  return route;
}

std::mt19937_64 seededStream(std::uint64_t seed, NoiseStream stream) {
  std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                    static_cast<std::uint32_t>(stream)};
  return std::mt19937_64(seq);
}

}  // namespace tessera::sim::detail
