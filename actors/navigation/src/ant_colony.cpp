// AntColonyRefiner: ants walking goal-wards on the costmap, pheromone on (cell, move) pairs.
#include <tessera/navigation/ant_colony.hpp>

#include <tessera/config/config_check.hpp>
#include <tessera/navigation/grid_planner.hpp>

#include <cmath>
#include <numbers>
#include <random>
#include <unordered_map>
#include <unordered_set>

namespace tessera::navigation {

void AntColonyOptions::validate() const {
  ConfigCheck()
      .require(ants >= 1, "ants", "must be >= 1", ants)
      .require(iterations >= 0, "iterations", "must be >= 0", iterations)
      .require(evaporation >= 0 && evaporation <= 1, "evaporation", "must be in [0, 1]",
               evaporation)
      .positive("deposit", deposit)
      .nonNegative("alpha", alpha)
      .nonNegative("nest_radius", nest_radius)
      .require(max_steps >= 1, "max_steps", "must be >= 1", max_steps)
      .require(max_cost >= 0 && max_cost <= cost::kMaxTraversable, "max_cost",
               "must be in [0, 252]", max_cost)
      .throwIfBad("ant colony");
}

AntColonyRefiner::AntColonyRefiner(const AntColonyOptions& options) : options_(options) {
  options_.validate();
}

namespace {

constexpr int kDx[8] = {1, 1, 0, -1, -1, -1, 0, 1};
constexpr int kDy[8] = {0, 1, 1, 1, 0, -1, -1, -1};

/// The move (0..7, counter-clockwise from +x) closest to the bearing from c to goal.
int goalOctant(const Eigen::Vector2i& c, const Eigen::Vector2i& goal) {
  const double bearing = std::atan2(goal.y() - c.y(), goal.x() - c.x());
  const int o = static_cast<int>(std::lround(bearing / (std::numbers::pi / 4)));
  return (o % 8 + 8) % 8;
}

}  // namespace

std::vector<Eigen::Vector2i> AntColonyRefiner::refine(const Costmap& map,
                                                      const std::vector<Eigen::Vector2i>& path,
                                                      AntColonySummary* summary) const {
  AntColonySummary local;
  AntColonySummary& s = summary ? *summary : local;
  s = {};
  const auto max_cost = static_cast<std::uint8_t>(options_.max_cost);
  std::vector<Eigen::Vector2i> best = shortenPath(map, path, max_cost);
  s.input_length = s.output_length = pathLength(map, best);
  if (path.size() < 3) return best;
  const Eigen::Vector2i start = path.front(), goal = path.back();

  auto open = [&](int col, int row) {
    return map.contains(col, row) && map.at(col, row) <= max_cost;
  };

  // The nest: cells near the start that the start sees.
  std::vector<Eigen::Vector2i> nest;
  const int r = static_cast<int>(std::ceil(options_.nest_radius / map.resolution));
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx) {
      const Eigen::Vector2i c = start + Eigen::Vector2i(dx, dy);
      if (std::hypot(dx, dy) * map.resolution > options_.nest_radius) continue;
      if (open(c.x(), c.y()) && lineOfSight(map, start, c, max_cost)) nest.push_back(c);
    }
  if (nest.empty()) return best;

  std::mt19937_64 rng(options_.seed);
  std::unordered_map<std::int64_t, double>
      tau;  // (cell index * 8 + move) -> pheromone; 1 if absent
  auto key = [&](const Eigen::Vector2i& c, int move) {
    return static_cast<std::int64_t>(map.index(c.x(), c.y())) * 8 + move;
  };
  auto pheromone = [&](std::int64_t k) {
    const auto it = tau.find(k);
    return it == tau.end() ? 1.0 : it->second;
  };
  std::uniform_int_distribution<std::size_t> pick_nest(0, nest.size() - 1);
  std::uniform_real_distribution<double> unit(0.0, 1.0);

  for (int iteration = 0; iteration < options_.iterations; ++iteration) {
    std::vector<std::pair<std::vector<std::int64_t>, double>> deposits;
    for (int ant = 0; ant < options_.ants; ++ant) {
      Eigen::Vector2i c = nest[pick_nest(rng)];
      std::vector<Eigen::Vector2i> walk{start, c};
      std::vector<std::int64_t> used;
      std::unordered_set<std::size_t> visited{map.index(c.x(), c.y())};
      bool arrived = false;
      for (int step = 0; step < options_.max_steps; ++step) {
        if (lineOfSight(map, c, goal, max_cost)) {
          arrived = true;
          break;
        }
        const int octant = goalOctant(c, goal);
        int moves[3];
        double weights[3];
        int n = 0;
        double total = 0;
        for (const int turn : {0, 1, 7}) {
          const int m = (octant + turn) % 8;
          const int nc = c.x() + kDx[m], nr = c.y() + kDy[m];
          if (!open(nc, nr) || visited.count(map.index(nc, nr))) continue;
          if (kDx[m] != 0 && kDy[m] != 0 && (!open(c.x() + kDx[m], c.y()) || !open(c.x(), nr)))
            continue;  // no squeezing past a corner
          moves[n] = m;
          weights[n] = std::pow(pheromone(key(c, m)), options_.alpha);
          total += weights[n++];
        }
        if (n == 0) break;  // a dead end: the ant is lost
        double u = unit(rng) * total;
        int chosen = n - 1;
        for (int i = 0; i < n; ++i) {
          if (u < weights[i]) {
            chosen = i;
            break;
          }
          u -= weights[i];
        }
        used.push_back(key(c, moves[chosen]));
        c += Eigen::Vector2i(kDx[moves[chosen]], kDy[moves[chosen]]);
        visited.insert(map.index(c.x(), c.y()));
        walk.push_back(c);
      }
      if (!arrived) continue;
      ++s.ants_arrived;
      if (walk.back() != goal) walk.push_back(goal);
      std::vector<Eigen::Vector2i> adjusted = shortenPath(map, walk, max_cost);
      const double length = pathLength(map, adjusted);
      deposits.emplace_back(std::move(used), length);
      if (length < s.output_length - 1e-9) {
        s.output_length = length;
        best = std::move(adjusted);
        ++s.improvements;
      }
    }
    for (auto& [k, value] : tau) value *= options_.evaporation;
    for (const auto& [keys, length] : deposits) {
      const double add = options_.deposit / std::max(length, map.resolution);
      for (const std::int64_t k : keys) {
        auto [it, inserted] = tau.try_emplace(k, options_.evaporation);  // 1, evaporated
        it->second += add;
      }
    }
  }
  return best;
}

}  // namespace tessera::navigation
