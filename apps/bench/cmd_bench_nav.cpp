// `tessera bench nav`: the closed navigation loop in the simulated office (the sim_nav profile)
// on N random reachable goals, plus the figures around it:
//  * the goal run: goals reached, collisions of the body with the true 3D world (walls and
//    furniture), mean time to goal, driven / shortest path, MCL's error in the map frame (no
//    alignment: the map is the world), and the share of one core the navigator's control (global
//    plans + dynamic window) takes per simulated second;
//  * global localisation: the same office with MCL started uniformly over the free space while
//    the robot drives the office route; the distance travelled until the estimate is within
//    0.3 m of the truth from then on (null when it never settles);
//  * A* and Dijkstra CPU time per plan on the 2000 x 2000 office costmap of `bench planner`.
#include "bench_commands.hpp"
#include "cli_inputs.hpp"
#include "nav_planning_bench.hpp"

#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/profile.hpp>

#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera::app {

namespace {

namespace fs = std::filesystem;

struct Options {
  int goals = 100;
  std::uint64_t seed = 1;
  double global_duration_s = 120;
  std::string out = "out/bench_nav";
  bool json = false;
};

const Summary& summaryOf(const RunReport& r, const std::string& actor) {
  for (const auto& a : r.actors)
    if (a.name == actor) return a.summary;
  throw std::runtime_error("bench nav: the run has no actor '" + actor + "'");
}

double number(const Summary& s, const std::string& key) {
  const auto it = s.find(key);
  if (it == s.end()) throw std::runtime_error("bench nav: the run reported no " + key);
  if (const auto* d = std::get_if<double>(&it->second)) return *d;
  if (const auto* i = std::get_if<std::int64_t>(&it->second)) return static_cast<double>(*i);
  throw std::runtime_error("bench nav: " + key + " is not a number");
}

RunReport runNav(const fs::path& dir, const std::vector<std::string>& overrides) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  auto profile = loadProfile(resolveProfilePath("sim_nav", profileSearchDirs()), overrides);
  RuntimeOptions ro;
  ro.show_progress = false;
  ro.output_dir = dir.string();
  ro.threads = 2;
  return buildRuntime(profile, ro)->run();
}

/// Position errors [m] of `estimate` against `truth` paired by stamp, and the truth's path
/// length up to each paired pose.
struct Track {
  std::vector<double> error, travelled;
};
Track track(const fs::path& estimate_file, const fs::path& truth_file) {
  const auto estimate = mapping::readTum(estimate_file);
  const auto truth = mapping::readTum(truth_file);
  Track t;
  std::size_t next = 0;
  double along = 0;
  for (const auto& [e, r] : evaluation::associateByTime(estimate, truth, {})) {
    for (; next < r; ++next)
      if (next > 0) along += (truth[next].position - truth[next - 1].position).norm();
    t.error.push_back((estimate[e].position - truth[r].position).norm());
    t.travelled.push_back(along);
  }
  return t;
}

}  // namespace

void addBenchNavCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "nav",
      "closed-loop navigation in the simulated office (sim_nav): random goals reached, "
      "collisions, time to goal, path length, MCL error, global localisation, planner times");
  auto o = std::make_shared<Options>();
  cmd->add_option("--goals", o->goals, "random reachable goals")->capture_default_str();
  cmd->add_option("--seed", o->seed, "seed of the goals")->capture_default_str();
  cmd->add_option("--global-duration", o->global_duration_s,
                  "[s] simulated time of the global-localisation run")
      ->capture_default_str();
  cmd->add_option("--out", o->out, "folder for the runs' outputs")->capture_default_str();
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->callback([o, &result] {
    if (o->goals < 1) throw std::runtime_error("bench nav: --goals must be at least 1");
    if (!(o->global_duration_s > 0))
      throw std::runtime_error("bench nav: --global-duration must be > 0");
    const fs::path out(o->out);

    std::cerr << "[bench nav] " << o->goals << " random goals in the simulated office ...\n";
    const RunReport goals = runNav(out / "goals", {"goals.random=" + std::to_string(o->goals),
                                                   "goals.seed=" + std::to_string(o->seed)});
    const Summary& g = summaryOf(goals, "goals");
    const Summary& sim = summaryOf(goals, "sim");
    const Summary& nav = summaryOf(goals, "nav");
    const Track mcl = track(out / "goals" / "trajectory.tum", out / "goals" / "ground_truth.tum");
    // The localizer's handler time per simulated second (10 Hz scans, TBB-parallel weighting
    // inside the handler, so CPU may be up to the worker count times this).
    double mcl_core_fraction = std::nan("");
    for (const auto& a : goals.actors)
      if (a.name == "mcl" && goals.sim_duration_s > 0)
        mcl_core_fraction = a.handler_total_s / goals.sim_duration_s;
    double mcl_mean = 0;
    for (double e : mcl.error) mcl_mean += e;
    if (!mcl.error.empty()) mcl_mean /= static_cast<double>(mcl.error.size());

    std::cerr << "[bench nav] global localisation while driving the office route ...\n";
    runNav(out / "global", {"sim.drive=route", "mcl.global=true", "goals.random=1",
                            "max_duration_s=" + std::to_string(o->global_duration_s)});
    const Track global =
        track(out / "global" / "trajectory.tum", out / "global" / "ground_truth.tum");
    // Converged at the first pose after which every error stays under 0.3 m.
    std::optional<double> global_travel;
    for (std::size_t i = global.error.size(); i-- > 0;) {
      if (global.error[i] >= 0.3) break;
      global_travel = global.travelled[i];
    }

    std::cerr << "[bench nav] global planners on the 2000 x 2000 office costmap ...\n";
    PlanningBenchOptions po;
    po.ant_colony = false;
    const PlanningBenchResult planning = runPlanningBench(po);
    const auto cpu = [&](const char* name) {
      const PlannerFigures* f = planning.find(name);
      return f ? f->cpu_ms_median : std::nan("");
    };

    const nlohmann::json j{
        {"machine", machineDescription()},
        {"goals", static_cast<std::int64_t>(number(g, "goals"))},
        {"reached", static_cast<std::int64_t>(number(g, "reached"))},
        {"collisions", static_cast<std::int64_t>(number(sim, "collisions"))},
        {"mean_time_to_goal_s", number(g, "mean_time_to_goal_s")},
        {"path_length_ratio", number(g, "path_length_ratio")},
        {"mcl_error_mean_m", mcl_mean},
        {"global_localisation_travel_m",
         global_travel ? nlohmann::json(*global_travel) : nlohmann::json(nullptr)},
        // A* as the navigator runs it: with its default landmark bounds (octile alone: text).
        {"astar_ms", cpu("astar_landmarks")},
        {"dijkstra_ms", cpu("dijkstra")},
        {"dwa_core_fraction", number(nav, "control_core_fraction")}};
    if (o->json) {
      std::cout << j.dump(2) << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << std::fixed << std::setprecision(3) << "goals reached        " << j["reached"]
              << " of " << j["goals"] << " (failed " << static_cast<int>(number(g, "failed"))
              << ", timed out " << static_cast<int>(number(g, "timed_out")) << ")\n"
              << "collisions           " << j["collisions"] << " (closest approach "
              << number(sim, "min_clearance_m") << " m beyond the body)\n"
              << "time to goal         " << number(g, "mean_time_to_goal_s") << " s mean\n"
              << "driven / shortest    " << number(g, "path_length_ratio") << "\n"
              << "MCL error            " << mcl_mean << " m mean (map frame, no alignment)\n"
              << "global localisation  "
              << (global_travel ? std::to_string(*global_travel) + " m travelled"
                                : std::string("did not settle within 0.3 m"))
              << "\n"
              << "A* / Dijkstra        " << cpu("astar_landmarks") << " / " << cpu("dijkstra")
              << " ms CPU per plan (2000 x 2000 cells; A* with " << po.landmarks
              << " landmark bounds, built in " << planning.landmarks_ms << " ms; octile alone "
              << cpu("astar") << " ms)\n"
              << "navigator control    " << number(nav, "control_core_fraction")
              << " of a core (plans + dynamic window), costmaps "
              << number(nav, "costmap_core_fraction") << ", sensors "
              << number(nav, "sensor_core_fraction") << "\n"
              << "MCL                  " << mcl_core_fraction
              << " of a core (handler time per simulated second; 10 Hz scans); with the "
                 "costmaps and sensor marking "
              << mcl_core_fraction + number(nav, "costmap_core_fraction") +
                     number(nav, "sensor_core_fraction")
              << "\n"
              << "outputs              " << out.string() << "/goals, " << out.string()
              << "/global\n";
    result = 0;
  });
}

}  // namespace tessera::app
