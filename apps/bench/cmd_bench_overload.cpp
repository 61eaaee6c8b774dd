// tessera bench overload: every profile with its sensors at F times real time (`tessera run P
// --set clock=paced --rate F`: simulated time runs F times faster than the wall clock and, unlike
// the default simulated clock, never waits for the actors, so each actor gets F times its usual
// load per second, as on a robot whose sensors outrun it). Per profile: did the run end (a
// reliable cycle that deadlocked would not: it is killed after a time limit), the keep_latest
// evictions (the designed overflow), messages lost on reliable subscriptions (published in the
// process but not handled: must be 0), the worst actor's inbox wait p99, and the data time
// covered per wall second (below F when a reliable mailbox held its source back). With --launch
// the profiles with process groups run as `tessera launch` deployments (one process per group),
// and what crosses between processes is judged by the launch's delivery ledger.
#include "bench_commands.hpp"
#include "child_process.hpp"
#include "cli_inputs.hpp"

#include <tessera/runtime/process_stats.hpp>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <thread>

namespace tessera::app {

namespace {

namespace fs = std::filesystem;

struct Options {
  std::vector<std::string> profiles;  // empty: every profile below whose inputs exist
  double factor = 10;
  double seconds = 10;  // wall seconds of paced data per profile (max_duration_s = F * this)
  std::string data = "../shared/data";
  std::string out = "out/bench_overload";
  bool json = false;
  bool launch = false;  // `tessera launch` the profiles with process groups, one process each
};

/// A profile and the settings it needs to run here; `needs` is a file that must exist.
struct Case {
  std::string profile;
  std::vector<std::string> sets;
  std::string needs;
};

std::vector<Case> allCases(const Options& o, const fs::path& out) {
  const std::string d = o.data;
  const std::string rgbd = "player.path=" + d + "/7scenes-redkitchen-rgbd";
  const std::string intel = "player.path=" + d + "/intel-lab-mrpt/intel.clf.gz";
  const std::string urg_log = d + "/mines-paristech-urg04lx-odometry/exp2.dat.gz";
  const std::string urg = "player.path=" + urg_log;
  return {
      {"sim_mapping", {}, ""},
      {"sim_slam", {}, ""},
      {"sim_slam_global", {}, ""},
      {"sim_slam_split", {}, ""},
      {"sim_multi_robot", {}, ""},
      {"sim_lines", {}, ""},
      {"sim_landmarks", {}, ""},
      {"sim_odometry", {}, ""},
      {"sim_room", {}, ""},
      {"sim_mcl", {"mcl.map_file=" + (out / "prep_sim_map" / "map.yaml").string()}, ""},
      {"sim_nav", {}, ""},
      {"sim_nav_slam", {}, ""},
      {"sim_nav_launch", {}, ""},
      {"sim_rgbd", {}, ""},
      {"sim_camera_network", {}, ""},
      {"sim_camera_slam", {}, ""},
      {"sim_camera_images", {}, ""},
      {"carmen_replay", {intel}, d + "/intel-lab-mrpt/intel.clf.gz"},
      {"carmen_rbpf", {intel}, d + "/intel-lab-mrpt/intel.clf.gz"},
      {"carmen_global", {intel}, d + "/intel-lab-mrpt/intel.clf.gz"},
      {"carmen_lines", {intel}, d + "/intel-lab-mrpt/intel.clf.gz"},
      {"urg_replay", {urg}, urg_log},
      {"urg_rbpf", {urg}, urg_log},
      {"rgbd_replay", {rgbd}, d + "/7scenes-redkitchen-rgbd"},
      {"rgbd_slam", {rgbd}, d + "/7scenes-redkitchen-rgbd"},
      {"rgbd_slam_split", {rgbd}, d + "/7scenes-redkitchen-rgbd"},
      {"victoria_park", {}, d + "/victoria-park-gtsam"},
      {"utias_landmarks", {}, d + "/utias-mrclam-dataset1"},
  };
}

/// The profiles with process groups, for --launch: `tessera launch` runs each group as a process.
std::vector<Case> launchCases(const Options& o) {
  const std::string rgbd_dir = o.data + "/7scenes-redkitchen-rgbd";
  return {
      {"sim_mapping", {}, ""},     {"sim_slam_split", {}, ""},
      {"sim_multi_robot", {}, ""}, {"sim_nav_launch", {}, ""},
      {"chaos_mapping", {}, ""},   {"rgbd_slam_split", {"player.path=" + rgbd_dir}, rgbd_dir},
  };
}

/// The run's command: `tessera run P --rate F`, or with --launch `tessera launch P` (the launch's
/// workers take the rate from the profile's sim_rate).
std::vector<std::string> commandFor(const Case& c, const Options& o, const fs::path& dir) {
  std::vector<std::string> args = {"tessera", o.launch ? "launch" : "run", c.profile, "--set",
                                   "clock=paced"};
  if (o.launch) {
    args.insert(args.end(), {"--set", "sim_rate=" + std::to_string(o.factor)});
  } else {
    args.insert(args.end(), {"--rate", std::to_string(o.factor), "--quiet"});
  }
  args.insert(args.end(), {"--set", "max_duration_s=" + std::to_string(o.factor * o.seconds),
                           "--out", dir.string()});
  for (const auto& s : c.sets) args.insert(args.end(), {"--set", s});
  return args;
}

nlohmann::json measure(const Case& c, const Options& o, const fs::path& out) {
  nlohmann::json r = {{"profile", c.profile}};
  if (!c.needs.empty() && !fs::exists(c.needs)) {
    r["skipped"] = "input " + c.needs + " not found";
    return r;
  }
  const fs::path dir = out / c.profile;
  fs::remove_all(dir);
  fs::create_directories(dir);
  const double limit = 3 * o.seconds + 60;
  const int code = runTesseraChild(commandFor(c, o, dir), dir / "run.log", limit);
  r["exit_code"] = code;
  r["finished"] = code == 0;
  if (code < 0) {
    r["error"] = "still running after " + std::to_string(static_cast<int>(limit)) +
                 " s (a deadlock?): killed; see " + (dir / "run.log").string();
    return r;
  }
  std::ifstream in(dir / "summary.json");
  if (!in) {
    r["error"] =
        "no summary.json (exit " + std::to_string(code) + "): see " + (dir / "run.log").string();
    return r;
  }
  const auto s = nlohmann::json::parse(in);
  std::uint64_t keep_latest_drops = 0, reliable_drops = 0, reliable_lost = 0;
  double worst_wait = 0;
  std::string worst_actor;
  std::string lost_where;
  for (const auto& [name, a] : s.at("actors").items()) {
    const double wait = a.value("queue_wait_p99_us", 0.0);
    if (wait > worst_wait) worst_wait = wait, worst_actor = name;
    if (!a.contains("subscriptions")) continue;
    for (const auto& [topic, sub] : a.at("subscriptions").items()) {
      const auto drops = sub.value("drops", std::uint64_t{0});
      if (sub.value("policy", "") != "reliable") {
        keep_latest_drops += drops;
        continue;
      }
      reliable_drops += drops;
      // A launch's summary holds one process's topic counts: its routes are counted below.
      if (o.launch) continue;
      // Published in this process but never handled by this reliable subscriber.
      const auto t = s.at("topics").find(topic);
      const std::uint64_t published =
          t == s.at("topics").end() ? 0 : t->value("messages", std::uint64_t{0});
      const std::uint64_t handled = sub.value("handled", std::uint64_t{0});
      if (published > handled) {
        reliable_lost += published - handled;
        lost_where = name + " <- " + topic;
      }
    }
  }
  // Between processes (a launch): the delivery ledger's routes. A reliable route loses nothing
  // while both ends live; a keep_latest one drops what its full queue evicted.
  for (const auto& route : s.value("delivery", nlohmann::json::array())) {
    const auto sent = route.value("sent", std::uint64_t{0});
    const auto received = route.value("received", std::uint64_t{0});
    if (route.value("reliable", false)) {
      if (route.value("lost_live", std::uint64_t{0}) > 0) {
        reliable_lost += route.value("lost_live", std::uint64_t{0});
        lost_where = route.value("to", std::string()) + " <- " +
                     route.value("topic", std::string()) + " from " +
                     route.value("from", std::string());
      }
    } else if (sent > received) {
      keep_latest_drops += sent - received;
    }
  }
  r["wall_s"] = s.value("wall_s", 0.0);
  r["data_s"] = s.value("data_duration_s", 0.0);
  r["keep_latest_drops"] = keep_latest_drops;
  r["reliable_drops"] = reliable_drops;
  r["reliable_lost"] = reliable_lost;
  if (!lost_where.empty()) r["reliable_lost_at"] = lost_where;
  r["queue_wait_p99_us"] = worst_wait;
  r["queue_wait_p99_actor"] = worst_actor;
  if (code != 0) r["error"] = s.value("stop_reason", std::string("exit ") + std::to_string(code));
  return r;
}

int run(const Options& o) {
  const fs::path out = o.out;
  fs::create_directories(out);
  std::vector<Case> cases = o.launch ? launchCases(o) : allCases(o, out);
  if (!o.profiles.empty()) {
    std::vector<Case> chosen;
    for (const auto& p : o.profiles) {
      const auto it =
          std::find_if(cases.begin(), cases.end(), [&](const Case& c) { return c.profile == p; });
      chosen.push_back(it != cases.end() ? *it : Case{p, {}, ""});
    }
    cases = chosen;
  }
  // sim_mcl localises on a map made beforehand: the known-pose mapping run makes it.
  if (std::any_of(cases.begin(), cases.end(), [](const Case& c) { return c.profile == "sim_mcl"; }))
    runTesseraChild(
        {"tessera", "run", "sim_mapping", "--quiet", "--out", (out / "prep_sim_map").string()},
        out / "prep_sim_map.log", 300);

  nlohmann::json results = nlohmann::json::array();
  int failed = 0;
  for (const auto& c : cases) {
    std::cerr << c.profile << " ..." << std::flush;
    const auto r = measure(c, o, out);
    if (r.contains("skipped")) {
      std::cerr << " skipped: " << r["skipped"].get<std::string>() << "\n";
    } else {
      const bool bad = !r.value("finished", false) || r.value("reliable_lost", 0) > 0 ||
                       r.value("reliable_drops", 0) > 0;
      failed += bad ? 1 : 0;
      std::cerr << (bad ? " PROBLEM" : " ok") << "\n";
    }
    results.push_back(r);
  }
  const nlohmann::json j = {{"machine", machineDescription()},
                            {"factor", o.factor},
                            {"command", o.launch ? "launch" : "run"},
                            {"seconds", o.seconds},
                            {"profiles", results}};
  if (o.json) {
    std::cout << j.dump(2) << "\n";
    return failed > 0 ? 1 : 0;
  }
  std::cout << "machine: " << machineDescription() << "\n"
            << "sensors at " << o.factor << "x real time, " << o.seconds << " s of wall time each\n"
            << std::left << std::setw(20) << "profile" << std::right << std::setw(9) << "ended"
            << std::setw(14) << "kl drops" << std::setw(14) << "rel. lost" << std::setw(14)
            << "wait p99 ms"
            << "  worst actor\n";
  for (const auto& r : results) {
    std::cout << std::left << std::setw(20) << r["profile"].get<std::string>() << std::right;
    if (r.contains("skipped")) {
      std::cout << "  skipped: " << r["skipped"].get<std::string>() << "\n";
      continue;
    }
    std::cout << std::setw(9) << (r.value("finished", false) ? "yes" : "NO") << std::fixed
              << std::setw(14) << r.value("keep_latest_drops", 0) << std::setw(14)
              << r.value("reliable_lost", 0) << std::setprecision(2) << std::setw(14)
              << r.value("queue_wait_p99_us", 0.0) / 1000.0 << "  "
              << r.value("queue_wait_p99_actor", std::string()) << "\n";
    if (r.contains("error")) std::cout << "    " << r["error"].get<std::string>() << "\n";
  }
  return failed > 0 ? 1 : 0;
}

}  // namespace

void addBenchOverloadCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "overload",
      "every profile with its sensors at F x real time: runs that end, keep_latest drops, 0 "
      "reliable messages lost, the inbox wait p99 (exit 1 when a run hangs or loses a reliable "
      "message)");
  auto o = std::make_shared<Options>();
  cmd->add_option("--profiles", o->profiles, "profiles to run (default: all that can run here)")
      ->delimiter(',');
  cmd->add_option("--factor", o->factor, "sensor rate factor (the run's --rate)")
      ->check(finiteNumberIn(0.1, 1000.0));
  cmd->add_option("--seconds", o->seconds, "wall seconds of data per profile")
      ->check(finiteNumberIn(1.0, 3600.0));
  cmd->add_option("--data", o->data, "datasets folder");
  cmd->add_option("--out", o->out, "folder for the runs' outputs");
  cmd->add_flag("--launch", o->launch,
                "`tessera launch` the profiles with process groups (one process each): drops and "
                "losses between processes from the launch's delivery counts");
  cmd->add_flag("--json", o->json, "print one JSON object");
  cmd->callback([o, &result] { result = run(*o); });
}

}  // namespace tessera::app
