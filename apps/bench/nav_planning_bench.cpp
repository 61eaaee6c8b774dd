// The global-planning benchmark (nav_planning_bench.hpp): synthetic office, timed planners.
#include "nav_planning_bench.hpp"

#include "bench_util.hpp"

#include <tessera/config/config_check.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <numbers>
#include <random>

#include <time.h>

namespace tessera::app {

namespace nav = tessera::navigation;

void PlanningBenchOptions::validate() const {
  ConfigCheck()
      .require(cells >= 100, "cells", "must be >= 100", cells)
      .positive("resolution", resolution)
      .require(pairs >= 1, "pairs", "must be >= 1", pairs)
      .require(repeat >= 1, "repeat", "must be >= 1", repeat)
      .positive("pair_distance", pair_distance)
      .require(landmarks >= 0 && landmarks <= 16, "landmarks", "must be in [0, 16]", landmarks)
      .require(pair_distance < cells * resolution, "pair_distance",
               "must be shorter than the map side", pair_distance)
      .throwIfBad("planning bench");
  inflation.validate();
  planner.validate();
  ant_colony_options.validate();
}

const PlannerFigures* PlanningBenchResult::find(const std::string& planner) const {
  for (const auto& r : results)
    if (r.planner == planner) return &r;
  return nullptr;
}

nav::Costmap makeOfficeCostmap(int cells, double resolution, std::uint64_t seed,
                               const nav::InflationOptions& inflation) {
  nav::Costmap map(cells, cells, resolution);
  std::mt19937_64 rng(seed);
  auto uniform = [&](double a, double b) { return std::uniform_real_distribution<>(a, b)(rng); };
  auto chance = [&](double p) { return std::bernoulli_distribution(p)(rng); };
  const double side = cells * resolution;
  const double wall = 0.1, door = 1.0;
  // Marks the cells whose centres lie in [x0, x1) × [y0, y1) [m] lethal.
  auto block = [&](double x0, double y0, double x1, double y1) {
    auto first = [&](double m) {
      return std::clamp(static_cast<int>(std::ceil(m / resolution - 0.5)), 0, cells);
    };
    for (int r = first(y0); r < first(y1); ++r)
      for (int c = first(x0); c < first(x1); ++c) map.at(c, r) = nav::cost::kLethal;
  };
  block(0, 0, side, wall);
  block(0, side - wall, side, side);
  block(0, 0, wall, side);
  block(side - wall, 0, side, side);

  // Columns of rooms; bands of rooms along y, every third band a corridor.
  std::vector<double> xs{0};
  while (xs.back() < side) {
    const double next = xs.back() + uniform(6, 10);
    xs.push_back(side - next < 4 ? side : next);
  }
  std::vector<double> ys{0};
  std::vector<bool> corridor;
  while (ys.back() < side) {
    const bool is_corridor = corridor.size() % 3 == 1;
    const double next = ys.back() + (is_corridor ? 2.4 : uniform(5, 8));
    ys.push_back(side - next < 4 ? side : next);
    corridor.push_back(is_corridor);
  }
  // A wall between bands across each column, with a door into every room.
  for (std::size_t b = 1; b + 1 < ys.size(); ++b)
    for (std::size_t i = 0; i + 1 < xs.size(); ++i) {
      const double x0 = xs[i], x1 = xs[i + 1], y = ys[b];
      const double d = uniform(x0 + 0.6, x1 - 0.6 - door);
      block(x0, y - wall / 2, d, y + wall / 2);
      block(d + door, y - wall / 2, x1, y + wall / 2);
    }
  // Walls between neighbouring rooms (not across corridors), half of them with a door.
  for (std::size_t b = 0; b + 1 < ys.size(); ++b) {
    if (corridor[b]) continue;
    const double y0 = ys[b], y1 = ys[b + 1];
    for (std::size_t i = 1; i + 1 < xs.size(); ++i) {
      const double x = xs[i];
      if (chance(0.5)) {
        const double d = uniform(y0 + 0.6, y1 - 0.6 - door);
        block(x - wall / 2, y0, x + wall / 2, d);
        block(x - wall / 2, d + door, x + wall / 2, y1);
      } else {
        block(x - wall / 2, y0, x + wall / 2, y1);
      }
    }
    // Desks and pillars, 0.9 m clear of the walls so that every door stays reachable.
    for (std::size_t i = 0; i + 1 < xs.size(); ++i) {
      const int items = std::uniform_int_distribution<int>(2, 5)(rng);
      for (int k = 0; k < items; ++k) {
        double w = 0.4, h = 0.4;
        if (!chance(0.2)) {
          w = uniform(1.2, 1.8);
          h = uniform(0.6, 0.9);
          if (chance(0.5)) std::swap(w, h);
        }
        const double lo_x = xs[i] + 0.9, hi_x = xs[i + 1] - 0.9 - w;
        const double lo_y = y0 + 0.9, hi_y = y1 - 0.9 - h;
        if (hi_x <= lo_x || hi_y <= lo_y) continue;
        const double x = uniform(lo_x, hi_x), y = uniform(lo_y, hi_y);
        block(x, y, x + w, y + h);
      }
    }
  }
  nav::inflate(map, inflation);
  return map;
}

double polylineCost(const nav::Costmap& map, const std::vector<Eigen::Vector2i>& cells,
                    const nav::GridPlannerOptions& options) {
  double total = 0;
  for (std::size_t i = 1; i < cells.size(); ++i) {
    const Eigen::Vector2d a = cells[i - 1].cast<double>().array() + 0.5;
    const Eigen::Vector2d b = cells[i].cast<double>().array() + 0.5;
    const double length = (b - a).norm() * map.resolution;
    const int n = std::max(1, static_cast<int>(std::ceil((b - a).norm() * 8)));
    for (int k = 0; k < n; ++k) {
      const Eigen::Vector2d p = a + (b - a) * ((k + 0.5) / n);
      const std::uint8_t c =
          map.at(static_cast<int>(std::floor(p.x())), static_cast<int>(std::floor(p.y())));
      const double counted = c == nav::cost::kUnknown ? options.unknown_cost : c;
      total += length / n * (1 + options.cost_weight * counted / nav::cost::kMaxTraversable);
    }
  }
  return total;
}

namespace {

/// CPU time of the calling thread [ms]: unlike wall time, not stretched by other processes.
double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

/// The nearest cell of cost 0 to `c` (by growing square rings), or `c` when there is none.
Eigen::Vector2i nearestFree(const nav::Costmap& map, const Eigen::Vector2i& c) {
  const int limit = std::max(map.width, map.height);
  for (int r = 0; r < limit; ++r)
    for (int dy = -r; dy <= r; ++dy)
      for (int dx = -r; dx <= r; ++dx) {
        if (std::max(std::abs(dx), std::abs(dy)) != r) continue;
        const Eigen::Vector2i q = c + Eigen::Vector2i(dx, dy);
        if (map.contains(q) && map.at(q) == nav::cost::kFree) return q;
      }
  return c;
}

struct Run {
  std::vector<Eigen::Vector2i> path;
  double cost = 0;
  std::size_t expanded = 0;
  bool ok = false;
};

}  // namespace

PlanningBenchResult runPlanningBench(const PlanningBenchOptions& options) {
  options.validate();
  PlanningBenchResult out;
  const auto map_start = std::chrono::steady_clock::now();
  const nav::Costmap map =
      makeOfficeCostmap(options.cells, options.resolution, options.seed, options.inflation);
  out.map_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - map_start)
          .count();
  out.width = map.width;
  out.height = map.height;
  out.resolution = map.resolution;

  const double side = options.cells * options.resolution;
  for (int k = 0; k < options.pairs; ++k) {
    const double bearing = 0.3 + k * std::numbers::pi / options.pairs;
    const Eigen::Vector2d half =
        0.5 * options.pair_distance * Eigen::Vector2d(std::cos(bearing), std::sin(bearing));
    const Eigen::Vector2d centre(side / 2, side / 2);
    PlanningPair p;
    p.start = nearestFree(map, map.cellOf(centre - half));
    p.goal = nearestFree(map, map.cellOf(centre + half));
    p.straight_m = (p.goal - p.start).cast<double>().norm() * map.resolution;
    out.pairs.push_back(p);
  }

  nav::GridPlannerOptions astar_options = options.planner, dijkstra_options = options.planner;
  astar_options.algorithm = nav::SearchAlgorithm::kAStar;
  dijkstra_options.algorithm = nav::SearchAlgorithm::kDijkstra;
  nav::GridPlanner astar(astar_options), dijkstra(dijkstra_options), astar_lm(astar_options);
  if (options.landmarks > 0) {
    const auto t0 = std::chrono::steady_clock::now();
    astar_lm.setLandmarks(
        std::make_shared<const nav::LandmarkBounds>(map, astar_options, options.landmarks));
    out.landmarks_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  }
  nav::GridPlanner& refined = options.landmarks > 0 ? astar_lm : astar;
  const nav::AntColonyRefiner colony(options.ant_colony_options);
  const auto los_cost = static_cast<std::uint8_t>(options.ant_colony_options.max_cost);

  auto search = [](nav::GridPlanner& planner, const nav::Costmap& m, const PlanningPair& p) {
    const nav::GridPath g = planner.plan(m, p.start, p.goal);
    return Run{g.cells, g.cost, g.expanded, g.ok()};
  };
  std::vector<std::pair<std::string, std::function<Run(const PlanningPair&)>>> planners{
      {"dijkstra", [&](const PlanningPair& p) { return search(dijkstra, map, p); }},
      {"astar", [&](const PlanningPair& p) { return search(astar, map, p); }},
  };
  if (options.landmarks > 0)
    planners.emplace_back("astar_landmarks",
                          [&](const PlanningPair& p) { return search(astar_lm, map, p); });
  planners.emplace_back("astar_los", [&](const PlanningPair& p) {
    Run r = search(refined, map, p);
    if (r.ok) r.path = nav::shortenPath(map, r.path, los_cost);
    return r;
  });
  if (options.ant_colony)
    planners.emplace_back("astar_los_aco", [&](const PlanningPair& p) {
      Run r = search(refined, map, p);
      if (r.ok) r.path = colony.refine(map, r.path);
      return r;
    });

  std::vector<std::vector<double>> ms(planners.size()), cpu_ms(planners.size());
  out.results.resize(planners.size());
  // Repetition -1 is the untimed warm-up (search buffers allocated); its paths give the figures,
  // which the later repetitions repeat exactly (every planner is deterministic).
  for (int rep = -1; rep < options.repeat; ++rep)
    for (const auto& pair : out.pairs)
      for (std::size_t k = 0; k < planners.size(); ++k) {
        const double cpu0 = threadCpuMs();
        const auto t0 = std::chrono::steady_clock::now();
        const Run run = planners[k].second(pair);
        const double elapsed =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count();
        if (rep >= 0) {
          ms[k].push_back(elapsed);
          cpu_ms[k].push_back(threadCpuMs() - cpu0);
          continue;
        }
        PlannerFigures& f = out.results[k];
        f.planner = planners[k].first;
        if (!run.ok) continue;
        ++f.solved;
        f.length_m += nav::pathLength(map, run.path);
        f.cost += !f.planner.starts_with("astar_los")
                      ? run.cost
                      : polylineCost(map, run.path, options.planner);
        f.expanded += static_cast<double>(run.expanded);
      }
  for (std::size_t k = 0; k < planners.size(); ++k) {
    PlannerFigures& f = out.results[k];
    f.ms_median = percentile(ms[k], 0.5);
    f.ms_p95 = percentile(ms[k], 0.95);
    f.cpu_ms_median = percentile(cpu_ms[k], 0.5);
    if (f.solved > 0) {
      f.length_m /= f.solved;
      f.cost /= f.solved;
      f.expanded /= f.solved;
    }
  }
  return out;
}

}  // namespace tessera::app
