// tessera bench soak: lifelong operation measured (docs/benchmarks.md#soak). Runs the lifelong
// profile (sim_lifelong: the simulated office driven lap after lap) for H hours of simulated
// time, as fast as the CPU allows, in a child process, and reports per hour: resident memory,
// CPU per scan, graph size and submaps made (from the run's resources.csv, sampled by its
// resource_monitor on the simulated clock), and the ATE of the live pose over that hour under
// one alignment of the whole run. False loop closures come from the loop detector's score
// against the simulator's truth. Writes soak.json and soak.svg (four panels against the hour)
// in the output folder; --json prints the object.
// An RGB-D profile (sim_rgbd_lifelong: its monitor counts keyframes) is judged by what it
// writes instead: the ATE of trajectory_optimized.tum (every frame moved with the optimised
// keyframes; 3D, rigid alignment) and its loops.csv's accepted loops against ground_truth.tum.
#include "bench_commands.hpp"
#include "child_process.hpp"
#include "cli_inputs.hpp"

#include <tessera/evaluation/loop_log.hpp>
#include <tessera/evaluation/loop_metrics.hpp>
#include <tessera/evaluation/resource_log.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/io/atomic_file.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/runtime/process_stats.hpp>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

namespace tessera::app {

namespace {

namespace fs = std::filesystem;

struct Options {
  double hours = 8.0;
  double period_h = 1.0;
  std::string profile = "sim_lifelong";
  std::vector<std::string> sets;
  std::string out = "out/bench_soak";
  bool json = false;
};

/// RMSE of the errors whose estimate stamp falls in [from, to) seconds after the first.
double windowRmse(const std::vector<mapping::TumPose>& est, const evaluation::AteResult& ate,
                  const std::vector<std::pair<std::size_t, std::size_t>>& pairs, double from_s,
                  double to_s) {
  if (est.empty()) return -1;
  const std::int64_t t0 = est.front().stamp_ns;
  double sum = 0;
  std::size_t n = 0;
  for (std::size_t k = 0; k < pairs.size() && k < ate.errors.size(); ++k) {
    const double t = static_cast<double>(est[pairs[k].first].stamp_ns - t0) * 1e-9;
    if (t < from_s || t >= to_s) continue;
    sum += ate.errors[k] * ate.errors[k];
    ++n;
  }
  return n > 0 ? std::sqrt(sum / static_cast<double>(n)) : -1;
}

/// One panel of the plot: `values` against hour, in a w x h box at (x, y).
void panel(std::ostream& svg, double x, double y, double w, double h, const std::string& title,
           const std::vector<double>& hours, const std::vector<double>& values) {
  svg << "<g transform='translate(" << x << "," << y << ")'>"
      << "<rect width='" << w << "' height='" << h << "' fill='none' stroke='#888'/>"
      << "<text x='4' y='-6' font-size='13'>" << title << "</text>";
  double hi = 0;
  for (const double v : values) hi = std::max(hi, v);
  hi = hi > 0 ? hi * 1.15 : 1.0;
  const double hmax = hours.empty() ? 1.0 : std::max(hours.back(), 1e-9);
  svg << "<text x='-4' y='10' font-size='10' text-anchor='end'>" << std::setprecision(3) << hi
      << "</text><text x='-4' y='" << h << "' font-size='10' text-anchor='end'>0</text>"
      << "<text x='" << w << "' y='" << h + 14 << "' font-size='10' text-anchor='end'>hour " << hmax
      << "</text><polyline fill='none' stroke='#1f77b4' stroke-width='2' points='";
  for (std::size_t i = 0; i < values.size(); ++i)
    svg << w * hours[i] / hmax << "," << h - h * values[i] / hi << " ";
  svg << "'/>";
  for (std::size_t i = 0; i < values.size(); ++i)
    svg << "<circle r='3' fill='#1f77b4' cx='" << w * hours[i] / hmax << "' cy='"
        << h - h * values[i] / hi << "'/>";
  svg << "</g>\n";
}

int run(const Options& o) {
  const fs::path out(o.out);
  const fs::path dir = out / "run";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const double seconds = o.hours * 3600.0;
  std::vector<std::string> args = {
      "tessera", "run", o.profile, "--quiet", "--out", dir.string(), "--set",
      "max_duration_s=" + std::to_string(seconds), "--set",
      // Enough laps for the hours: the office loop takes ~8 min.
      "sim.laps=" + std::to_string(static_cast<long>(seconds / 60.0) + 2), "--set",
      "monitor.period_s=" + std::to_string(o.period_h * 3600.0)};
  for (const auto& s : o.sets) {
    args.push_back("--set");
    args.push_back(s);
  }
  if (!o.json)
    std::cerr << "soak: " << o.profile << " for " << o.hours
              << " simulated hours (log: " << (dir / "run.log").string() << ") ...\n";
  const auto t0 = std::chrono::steady_clock::now();
  const int code = runTesseraChild(args, dir / "run.log");
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (code != 0) {
    std::cerr << "soak: the run failed (exit " << code << "): see " << (dir / "run.log").string()
              << "\n";
    return 1;
  }
  const auto rows = evaluation::readResourceLog(dir / "resources.csv");
  // RGB-D SLAM: the live pose is the front end's, which loops never correct; the SLAM answer is
  // every frame moved with the optimised keyframes, in 3D.
  const bool rgbd = fs::exists(dir / "trajectory_optimized.tum");
  const auto est = mapping::readTum(dir / (rgbd ? "trajectory_optimized.tum" : "trajectory.tum"));
  const auto ref = mapping::readTum(dir / "ground_truth.tum");
  evaluation::AteOptions ate_options;
  ate_options.dimension = rgbd ? evaluation::Dimension::kSpatial : evaluation::Dimension::kPlanar;
  const auto ate = evaluation::computeAte(est, ref, ate_options);
  const auto pairs = evaluation::associateByTime(est, ref, ate_options.association);

  nlohmann::json summary;
  std::ifstream(dir / "summary.json") >> summary;
  const auto& loops = summary["actors"]["loops"];
  std::int64_t false_loops = loops.value("loops_false", std::int64_t{-1});
  if (false_loops < 0 && fs::exists(dir / "loops.csv")) {
    const auto checked = evaluation::checkLoops(
        evaluation::acceptedLoops(evaluation::readLoopLog(dir / "loops.csv")), ref);
    false_loops = static_cast<std::int64_t>(checked.false_loops);
  }

  // One point per period: the row at its end; CPU per scan and ATE over the period.
  nlohmann::json series = nlohmann::json::array();
  std::vector<double> hours, rss, cpu, ates, nodes;
  const double period_s = o.period_h * 3600.0;
  for (std::size_t i = 1; i < rows.size(); ++i) {
    const evaluation::ResourceSample& a = rows[i - 1];
    const evaluation::ResourceSample& b = rows[i];
    if (b.t_s - a.t_s < 0.5 * period_s) continue;  // the row written at stop, just after the last
    const double scans = b.scans - a.scans;
    const double hour = b.t_s / 3600.0;
    const double ate_m = windowRmse(est, ate, pairs, a.t_s, b.t_s);
    series.push_back({{"hour", hour},
                      {"rss_mb", b.rss_mb},
                      {"cpu_ms_per_scan", scans > 0 ? 1000.0 * (b.cpu_s - a.cpu_s) / scans : 0.0},
                      {"ate_m", ate_m},
                      {"submaps", b.submaps},
                      {"graph_nodes", b.graph_nodes}});
    hours.push_back(hour);
    rss.push_back(b.rss_mb);
    cpu.push_back(series.back()["cpu_ms_per_scan"].get<double>());
    ates.push_back(std::max(0.0, ate_m));
    nodes.push_back(b.graph_nodes);
  }
  const nlohmann::json result = {{"machine", machineDescription()},
                                 {"hours", o.hours},
                                 {"series", series},
                                 {"false_loops", false_loops}};
  {
    io::AtomicFile f(out / "soak.json");
    f.stream() << result.dump(2) << "\n";
    f.commit();
    io::AtomicFile svg(out / "soak.svg");
    auto& s = svg.stream();
    s << "<svg xmlns='http://www.w3.org/2000/svg' width='900' height='560' "
         "font-family='sans-serif'>\n<text x='20' y='24' font-size='16'>tessera bench soak: "
      << o.profile << ", " << o.hours << " simulated hours, " << false_loops
      << " false loop closures</text>\n";
    panel(s, 70, 60, 340, 190, "RSS [MiB]", hours, rss);
    panel(s, 520, 60, 340, 190, "CPU per scan [ms]", hours, cpu);
    panel(s, 70, 320, 340, 190,
          rgbd ? "ATE of the optimised frames in the hour [m]"
               : "ATE of the live pose in the hour [m]",
          hours, ates);
    panel(s, 520, 320, 340, 190,
          rgbd ? "graph nodes (keyframes kept)" : "graph nodes (submaps kept)", hours, nodes);
    s << "</svg>\n";
    svg.commit();
  }
  if (o.json) {
    std::cout << result.dump(2) << "\n";
    return 0;
  }
  std::cout << "machine: " << machineDescription() << "\n"
            << o.profile << ": " << o.hours << " simulated hours in " << std::fixed
            << std::setprecision(0) << wall_s << " s wall; ATE of the whole run "
            << std::setprecision(3) << ate.translation.rmse << " m; false loop closures "
            << false_loops << "\n"
            << std::setw(6) << "hour" << std::setw(10) << "RSS MiB" << std::setw(14)
            << "CPU ms/scan" << std::setw(10) << "ATE m" << std::setw(10) << "submaps"
            << std::setw(13) << "graph nodes\n";
  for (const auto& r : series)
    std::cout << std::setw(6) << std::setprecision(2) << r["hour"].get<double>() << std::setw(10)
              << std::setprecision(1) << r["rss_mb"].get<double>() << std::setw(14)
              << std::setprecision(2) << r["cpu_ms_per_scan"].get<double>() << std::setw(10)
              << std::setprecision(3) << r["ate_m"].get<double>() << std::setw(10)
              << std::setprecision(0) << r["submaps"].get<double>() << std::setw(12)
              << r["graph_nodes"].get<double>() << "\n";
  std::cout << "wrote " << (out / "soak.json").string() << ", " << (out / "soak.svg").string()
            << "\n";
  return 0;
}

}  // namespace

void addBenchSoakCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "soak",
      "lifelong operation: the simulated office driven for H simulated hours; RSS, CPU per "
      "scan, ATE and graph size per hour, false loop closures (soak.json, soak.svg)");
  auto o = std::make_shared<Options>();
  cmd->add_option("--hours", o->hours, "simulated hours to drive")
      ->check(finiteNumberIn(0.01, 1000.0));
  cmd->add_option("--period-hours", o->period_h, "hours between samples (1: one row per hour)")
      ->check(finiteNumberIn(0.001, 1000.0));
  cmd->add_option("--profile", o->profile,
                  "profile to soak (needs the resource_monitor actor 'monitor', a 'sim' "
                  "simulator and trajectory.tum / ground_truth.tum writers); sim_rgbd_lifelong: "
                  "RGB-D SLAM");
  cmd->add_option("--set", o->sets, "override passed to the run (ACTOR.KEY=VALUE)");
  cmd->add_option("--out", o->out, "folder for the run and the report");
  cmd->add_flag("--json", o->json, "print one JSON object");
  cmd->callback([o, &result] { result = run(*o); });
}

}  // namespace tessera::app
