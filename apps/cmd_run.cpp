#include "cli_inputs.hpp"
#include "commands.hpp"

#include <tessera/io/atomic_file.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/profile.hpp>
#include <tessera/runtime/registry.hpp>

#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>

namespace tessera::app {

namespace fs = std::filesystem;

namespace {

nlohmann::json toJson(const SummaryValue& v) {
  return std::visit([](const auto& x) { return nlohmann::json(x); }, v);
}

}  // namespace

nlohmann::json summaryJson(const Profile& profile, const RunReport& r) {
  nlohmann::json j;
  j["profile"] = profile.name;
  j["wall_s"] = r.wall_s;
  j["cpu_s"] = r.cpu_s;
  j["peak_rss_mb"] = r.peak_rss_mb;
  j["data_duration_s"] = r.sim_duration_s;
  j["realtime_factor"] = r.wall_s > 0 ? r.sim_duration_s / r.wall_s : 0.0;
  j["interrupted"] = r.interrupted;
  j["stop_reason"] = r.stop_reason;
  nlohmann::json actors = nlohmann::json::object();
  for (const auto& a : r.actors) {
    nlohmann::json aj;
    aj["messages_in"] = a.messages_in;
    aj["messages_out"] = a.messages_out;
    aj["timer_calls"] = a.timer_calls;
    aj["drops"] = a.drops;
    aj["max_queue_depth"] = a.max_queue_depth;
    aj["handler_p50_us"] = a.handler_p50_us;
    aj["handler_p99_us"] = a.handler_p99_us;
    aj["handler_total_s"] = a.handler_total_s;
    aj["queue_wait_p50_us"] = a.queue_wait_p50_us;
    aj["queue_wait_p99_us"] = a.queue_wait_p99_us;
    nlohmann::json subs = nlohmann::json::object();
    for (const auto& s : a.subscriptions)
      subs[s.topic] = {{"policy", s.reliable ? "reliable" : "keep_latest"},
                       {"handled", s.handled},
                       {"drops", s.drops}};
    aj["subscriptions"] = subs;
    for (const auto& [k, v] : a.summary) {
      aj[k] = toJson(v);
      // Actor figures are also top-level keys (scripts read e.g. summary["scans_processed"]);
      // on a clash the later actor's key is prefixed with its name.
      if (j.contains(k))
        j[a.name + "." + k] = toJson(v);
      else
        j[k] = toJson(v);
    }
    actors[a.name] = aj;
  }
  j["actors"] = actors;
  nlohmann::json topics = nlohmann::json::object();
  for (const auto& t : r.topics) topics[t.name] = {{"messages", t.messages}, {"bytes", t.bytes}};
  j["topics"] = topics;
  return j;
}

void addRunOptions(CLI::App& cmd, RunSettings& s) {
  cmd.add_option("--set", s.sets, "override: ACTOR.KEY=VALUE, KEY=VALUE (repeatable)");
  cmd.add_option("--threads", s.threads,
                 "executor threads (0: one with a simulated clock, all cores otherwise)");
  cmd.add_flag("--quiet", s.quiet, "no progress line and no metrics table");
  addViewOptions(cmd, s);
}

void addViewOptions(CLI::App& cmd, RunSettings& s) {
  cmd.add_option("--view", s.view_port,
                 "serve the live viewer on PORT: the page at http://127.0.0.1:PORT/, Foxglove "
                 "Studio at ws://127.0.0.1:PORT (simulated clocks then run at real time)")
      ->check(CLI::Range(0, 65535));
  cmd.add_option("--view-address", s.view_address,
                 "interface the viewer listens on (0.0.0.0: every one; set --view-token)");
  cmd.add_option("--view-token", s.view_token, "token every viewer request must carry");
}

std::string uniqueActorName(const Profile& profile, const std::string& base) {
  std::string name = base;
  for (int i = 2;; ++i) {
    const bool taken = std::any_of(profile.actors.begin(), profile.actors.end(),
                                   [&](const ActorSpec& a) { return a.name == name; });
    if (!taken) return name;
    name = base + "_" + std::to_string(i);
  }
}

ActorSpec actorSpec(const std::string& name, const std::string& type, const YAML::Node& params) {
  ActorSpec spec;
  spec.name = name;
  spec.type = type;
  spec.params = Params(params, "tessera " + type + " (command line)");
  return spec;
}

YAML::Node viewerParams(const RunSettings& s, const std::vector<ActorParams>& actors) {
  YAML::Node params;
  params["port"] = s.view_port;
  params["address"] = s.view_address;
  if (!s.view_token.empty()) params["token"] = s.view_token;
  bool localises = false;
  for (const auto& [type, node] : actors) {
    YAML::Node p = node;  // a handle: edits reach the caller's node
    // Initial poses where a localiser listens: its initial_pose subscription is switched on (it
    // stays off without --view because nothing would publish it). Goals are always offered:
    // without a navigator they are only recorded.
    if (type == "monte_carlo_localizer") {
      localises = true;
      if (!p["initial_pose_topic"]) p["initial_pose_topic"] = true;
    }
    // A map assembler that publishes only at the end (publish_period_s 0, sim_slam_global's
    // default for batch runs) would show nothing until then: once a second instead.
    if (type == "map_assembler" &&
        !(p["publish_period_s"] && p["publish_period_s"].as<double>(0) > 0))
      p["publish_period_s"] = 1.0;
  }
  if (!localises) params["initial_pose_topic"] = "";
  return params;
}

void applyViewOptions(Profile& profile, const RunSettings& s, bool rate_given) {
  if (s.view_port < 0) return;
  std::vector<ActorParams> actors;
  for (const auto& a : profile.actors) {
    YAML::Node p = YAML::Clone(a.params.node());
    if (!p.IsMap()) p = YAML::Node(YAML::NodeType::Map);
    actors.emplace_back(a.type, p);
  }
  const YAML::Node params = viewerParams(s, actors);
  for (std::size_t i = 0; i < actors.size(); ++i)
    profile.actors[i].params = Params(actors[i].second, profile.actors[i].params.where());
  profile.actors.push_back(actorSpec(uniqueActorName(profile, "viewer"), "viewer", params));
  if (!rate_given && profile.clock == ClockKind::kSimulated && profile.sim_rate == 0) {
    profile.sim_rate = 1;
    std::cerr << "note: --view runs the simulated clock at real time (--rate 0: as fast as "
                 "possible)\n";
  }
}

int runProfile(const Profile& profile, const std::string& verb, const RunSettings& s,
               RunReport* report_out) {
  RuntimeOptions options;
  options.threads = s.threads;
  options.show_progress = !s.quiet;
  if (!s.out.empty()) {
    fs::create_directories(s.out);
    options.output_dir = fs::absolute(s.out).lexically_normal().string();
  }
  auto runtime = buildRuntime(profile, options);

  std::cerr << "tessera " << verb << " " << profile.name << " (" << profile.path << ")\n";
  if (!profile.description.empty()) std::cerr << "  " << profile.description << "\n";
  for (const auto& a : profile.actors) {
    std::cerr << "  actor " << std::left << std::setw(22) << a.name << std::setw(20) << a.type;
    auto subs = runtime->subscriptionsOf(a.name);
    auto pubs = runtime->publicationsOf(a.name);
    if (!subs.empty()) {
      std::cerr << " in:";
      for (const auto& sub : subs) std::cerr << " " << sub;
    }
    if (!pubs.empty()) {
      std::cerr << " out:";
      for (const auto& pub : pubs) std::cerr << " " << pub;
    }
    std::cerr << "\n";
  }
  std::cerr << "  clock: "
            << (profile.clock == ClockKind::kSimulated ? "simulated"
                : profile.clock == ClockKind::kPaced   ? "paced (never waits for the actors)"
                                                       : "wall")
            << (profile.clock == ClockKind::kSimulated && profile.sim_rate == 0
                    ? " (as fast as possible)"
                    : "")
            << ", output: "
            << (options.output_dir.empty() ? "(none; use --out DIR)" : options.output_dir)
            << "\n  Ctrl-C stops cleanly (outputs are still written)\n";

  runtime->installSignalHandlers();
  const RunReport report = runtime->run();
  if (!s.quiet) std::cerr << "\n" << report.table();
  std::cerr << "stopped: " << report.stop_reason << "\n";
  std::cerr << std::fixed << std::setprecision(2) << "data " << report.sim_duration_s << " s in "
            << report.wall_s << " s wall, " << report.cpu_s << " s CPU, peak RSS "
            << report.peak_rss_mb << " MB\n";
  bool summary_failed = false;
  if (!options.output_dir.empty()) {
    const auto j = summaryJson(profile, report);
    try {
      tessera::io::writeFileAtomically(fs::path(options.output_dir) / "summary.json",
                                       j.dump(2) + "\n");
    } catch (const std::exception& e) {
      std::cerr << "error: " << e.what() << "\n";
      summary_failed = true;
    }
    std::cerr << "outputs in " << options.output_dir << ":\n";
    std::vector<std::string> files;
    for (const auto& e : fs::directory_iterator(options.output_dir)) {
      if (e.is_regular_file()) files.push_back(e.path().filename().string());
    }
    std::sort(files.begin(), files.end());
    for (const auto& f : files)
      std::cerr << "  " << (fs::path(options.output_dir) / f).string() << "\n";
  }
  const bool actor_failure = report.interrupted && report.stop_reason.rfind("actor '", 0) == 0;
  if (actor_failure) std::cerr << "error: " << report.stop_reason << "\n";
  if (report_out != nullptr) *report_out = report;
  return actor_failure || summary_failed ? 1 : (report.interrupted ? 130 : 0);
}

void addRunCommand(CLI::App& app, int& result) {
  auto* cmd = app.add_subcommand("run", "run a profile in one process");
  struct Args {
    std::string profile;
    RunSettings run;
    double rate = -1;
  };
  auto args = std::make_shared<Args>();
  cmd->add_option("profile", args->profile, "profile name (apps/profiles/NAME.yaml) or path")
      ->required();
  cmd->add_option("--out", args->run.out,
                  "output folder (created); default: none, nothing is written");
  cmd->add_option("--rate", args->rate, "simulated clock pace: 0 as fast as possible, 1 real time");
  addRunOptions(*cmd, args->run);
  cmd->callback([args, &result] {
    const std::string path = resolveProfilePath(args->profile, profileSearchDirs());
    Profile profile = loadProfile(path, args->run.sets);
    if (args->rate >= 0) profile.sim_rate = args->rate;
    applyViewOptions(profile, args->run, args->rate >= 0);
    result = runProfile(profile, "run", args->run);
  });
}

void addActorsCommand(CLI::App& app, int& result) {
  auto* cmd = app.add_subcommand("actors", "list the actor types a profile can name, with options");
  auto type = std::make_shared<std::string>();
  cmd->add_option("type", *type, "show only this type");
  cmd->callback([type, &result] {
    const auto& entries = ActorRegistry::instance().entries();
    bool found = false;
    for (const auto& [name, entry] : entries) {
      if (!type->empty() && name != *type) continue;
      found = true;
      std::cout << name << " - " << entry.summary << "\n";
      const auto rows = entry.options();
      std::size_t width = 20;  // nested keys (rbpf.grid.log_odds.miss) widen the column
      for (const auto& row : rows) width = std::max(width, row[0].size());
      for (const auto& row : rows) {
        std::cout << "    " << std::left << std::setw(static_cast<int>(width + 2)) << row[0]
                  << std::setw(16) << row[1] << row[2] << "\n";
      }
    }
    if (!found) {
      std::cerr << "error: unknown actor type '" << *type << "'\n";
      result = 2;
    }
  });
}

}  // namespace tessera::app
