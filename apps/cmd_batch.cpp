// tessera batch: a recorded RGB-D sequence reprocessed as map tasks and one reduce
// (docs/architecture.md#batch-reprocessing). Map: the sequence is cut into shards of consecutive
// frames that overlap by a few frames, and each shard's player and front end (the profile's own
// actors) track it in a worker process of their own, recording keyframes and poses. Reduce: a
// shard_stitcher joins the recordings in one frame and feeds the rest of the profile (loop
// detector, keyframe graph, mapper, writers). --shard K runs one map task (on any host that sees
// the dataset and the output folder), --reduce the reduce alone.
#include "child_process.hpp"
#include "cli_inputs.hpp"
#include "commands.hpp"

#include <tessera/io/atomic_file.hpp>
#include <tessera/players/rgbd_player.hpp>
#include <tessera/runtime/registry.hpp>

#include <sys/wait.h>
#include <yaml-cpp/yaml.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <thread>

namespace tessera::app {

namespace fs = std::filesystem;

namespace {

struct BatchArgs {
  std::string profile;
  int workers = 0;  // 0: one per core
  int shards = 0;   // 0: = workers
  int overlap = 5;
  int shard = -1;  // >= 0: this map task only
  bool reduce_only = false;
  RunSettings run;
};

/// The global name of an actor's local topic (its remap, else its namespace).
std::string globalName(const ActorSpec& a, const std::string& local) {
  return globalTopicName(a.remap, a.topic_namespace, local);
}

/// The profile's player and front end, the actors a map task runs.
struct FrontActors {
  std::size_t player = 0, front_end = 0;
};

FrontActors findFrontActors(const Profile& p) {
  std::vector<std::size_t> players, front_ends;
  for (std::size_t i = 0; i < p.actors.size(); ++i) {
    if (p.actors[i].type == "rgbd_player") players.push_back(i);
    if (p.actors[i].type == "rgbd_front_end") front_ends.push_back(i);
  }
  if (players.size() != 1 || front_ends.size() != 1)
    throw ConfigError("batch: " + p.path + " has " + std::to_string(players.size()) +
                      " rgbd_player and " + std::to_string(front_ends.size()) +
                      " rgbd_front_end actors; a batch needs exactly one of each (e.g. rgbd_slam)");
  return {players.front(), front_ends.front()};
}

struct Shard {
  std::size_t first = 0, last = 0;  // frames played, inclusive
};

/// S shards over the frames the player would play, each extended by `overlap` frames into the
/// next one (the frames the stitcher joins them by).
std::vector<Shard> planShards(const Profile& p, const FrontActors& f, int count, int overlap) {
  const ActorSpec& spec = p.actors[f.player];
  const auto actor = ActorRegistry::instance().create(spec.type, spec.params);
  const auto* player = dynamic_cast<const players::RgbdPlayerActor*>(actor.get());
  if (!player) throw ConfigError("batch: actor '" + spec.name + "' is not an rgbd_player");
  const std::size_t begin = player->beginFrame(), end = player->endFrame();
  const std::size_t n = end - begin;
  if (static_cast<std::size_t>(count) * 2 > n)
    throw ConfigError("batch: " + std::to_string(count) + " shards over " + std::to_string(n) +
                      " frames: at least 2 frames per shard are needed (use fewer --shards)");
  std::vector<Shard> out;
  for (int k = 0; k < count; ++k) {
    const std::size_t a = begin + n * static_cast<std::size_t>(k) / static_cast<std::size_t>(count);
    const std::size_t b =
        begin + n * static_cast<std::size_t>(k + 1) / static_cast<std::size_t>(count);
    out.push_back({a, std::min(end, b + static_cast<std::size_t>(overlap)) - 1});
  }
  return out;
}

fs::path shardDir(const std::string& out, int k) {
  return fs::path(out) / ("shard_" + std::to_string(k));
}

/// Map task k: the player (limited to the shard's frames) and the front end, and a recorder.
int runMapTask(const Profile& p, const FrontActors& f, const Shard& s, int k,
               const BatchArgs& args) {
  Profile map = p;
  map.name = p.name + "_shard_" + std::to_string(k);
  map.clock = ClockKind::kSimulated;
  map.sim_rate = 0;  // offline: as fast as the front end tracks
  ActorSpec player = p.actors[f.player];
  YAML::Node params = YAML::Clone(player.params.node());
  params["first_frame"] = static_cast<std::int64_t>(s.first);
  params["last_frame"] = static_cast<std::int64_t>(s.last);
  player.params = Params(params, player.params.where());
  const ActorSpec& front = p.actors[f.front_end];
  YAML::Node rec;
  rec["path"] = "shard.trec";
  rec["topics"].push_back(globalName(front, "keyframes"));
  rec["topics"].push_back(globalName(front, "camera_pose"));
  rec["topics"].push_back(globalName(player, "ground_truth"));
  map.actors = {player, front};
  map.actors.push_back(actorSpec(uniqueActorName(map, "shard_recorder"), "recorder", rec));
  RunSettings settings = args.run;
  settings.out = shardDir(args.run.out, k).string();
  settings.view_port = -1;
  return runProfile(map, "batch", settings);
}

/// The reduce: the profile without its player and front end, fed by a shard_stitcher.
int runReduce(const Profile& p, const FrontActors& f, int shards, const BatchArgs& args,
              RunReport* report) {
  Profile reduce = p;
  reduce.name = p.name + "_reduce";
  reduce.clock = ClockKind::kSimulated;
  reduce.sim_rate = 0;
  reduce.actors.clear();
  for (std::size_t i = 0; i < p.actors.size(); ++i)
    if (i != f.player && i != f.front_end) reduce.actors.push_back(p.actors[i]);
  YAML::Node params;
  for (int k = 0; k < shards; ++k) {
    const fs::path rec = shardDir(args.run.out, k) / "shard.trec";
    if (!fs::exists(rec))
      throw ConfigError("batch: " + rec.string() + " is missing: run its map task first (tessera " +
                        "batch " + args.profile + " --shard " + std::to_string(k) + " --shards " +
                        std::to_string(shards) + " --out " + args.run.out + ")");
    params["recordings"].push_back(fs::absolute(rec).string());
  }
  const ActorSpec& front = p.actors[f.front_end];
  params["keyframes_topic"] = globalName(front, "keyframes");
  params["poses_topic"] = globalName(front, "camera_pose");
  params["ground_truth_topic"] = globalName(p.actors[f.player], "ground_truth");
  ActorSpec stitcher = actorSpec(uniqueActorName(reduce, "stitcher"), "shard_stitcher", params);
  stitcher.remap = {{"keyframes", globalName(front, "keyframes")},
                    {"camera_pose", globalName(front, "camera_pose")},
                    {"ground_truth", globalName(p.actors[f.player], "ground_truth")}};
  reduce.actors.insert(reduce.actors.begin(), stitcher);
  RunSettings settings = args.run;
  settings.view_port = -1;
  return runProfile(reduce, "batch", settings, report);
}

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct MapResult {
  int code = -1;
  double wall_s = 0;
};

/// Runs every map task in worker processes, at most `workers` at once; prints each as it ends.
std::vector<MapResult> runMapTasks(const std::vector<Shard>& shards, int workers,
                                   const BatchArgs& args) {
  std::vector<MapResult> results(shards.size());
  std::map<pid_t, std::pair<int, std::chrono::steady_clock::time_point>> running;
  std::size_t next = 0;
  const auto start = [&](int k) {
    const fs::path dir = shardDir(args.run.out, k);
    fs::create_directories(dir);
    std::vector<std::string> argv = {"tessera",
                                     "batch",
                                     args.profile,
                                     "--shard",
                                     std::to_string(k),
                                     "--shards",
                                     std::to_string(shards.size()),
                                     "--overlap",
                                     std::to_string(args.overlap),
                                     "--out",
                                     args.run.out,
                                     "--quiet"};
    if (args.run.threads > 0) {
      argv.push_back("--threads");
      argv.push_back(std::to_string(args.run.threads));
    }
    for (const auto& s : args.run.sets) {
      argv.push_back("--set");
      argv.push_back(s);
    }
    const pid_t pid = spawnTessera(argv, dir / "log.txt");
    running[pid] = {k, std::chrono::steady_clock::now()};
  };
  while (next < shards.size() || !running.empty()) {
    while (next < shards.size() && static_cast<int>(running.size()) < workers)
      start(static_cast<int>(next++));
    int status = 0;
    const pid_t pid = ::waitpid(-1, &status, 0);
    if (pid < 0) break;
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    const int k = it->second.first;
    results[k].wall_s = secondsSince(it->second.second);
    results[k].code = exitCodeOf(status);
    running.erase(it);
    std::cerr << "batch: shard " << k << " (frames " << shards[k].first << "-" << shards[k].last
              << ") " << (results[k].code == 0 ? "done" : "FAILED") << " in " << std::fixed
              << std::setprecision(1) << results[k].wall_s << " s"
              << (results[k].code == 0
                      ? ""
                      : ": see " + (shardDir(args.run.out, k) / "log.txt").string())
              << "\n";
  }
  return results;
}

int runBatch(const BatchArgs& args) {
  if (args.run.out.empty())
    throw ConfigError("batch: --out DIR is required (the shards' recordings go there)");
  const std::string path = resolveProfilePath(args.profile, profileSearchDirs());
  const Profile profile = loadProfile(path, args.run.sets);
  const FrontActors front = findFrontActors(profile);
  const int cores = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const int workers = args.workers > 0 ? args.workers : cores;
  const int count = args.shards > 0 ? args.shards : workers;
  if (args.overlap < 1 || args.overlap > 100)
    throw ConfigError("batch: --overlap " + std::to_string(args.overlap) +
                      ": expected 1..100 frames shared by neighbouring shards");
  if (args.shard >= count)
    throw ConfigError("batch: --shard " + std::to_string(args.shard) + " with --shards " +
                      std::to_string(count) + ": expected 0.." + std::to_string(count - 1));

  if (args.reduce_only) return runReduce(profile, front, count, args, nullptr);
  const std::vector<Shard> shards = planShards(profile, front, count, args.overlap);
  if (args.shard >= 0) return runMapTask(profile, front, shards[args.shard], args.shard, args);

  std::cerr << "batch: " << shards.size() << " shards of " << profile.name << " ("
            << shards.front().first << "-" << shards.back().last << ", " << args.overlap
            << " frames overlap) on " << workers << " worker process(es)\n";
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<MapResult> maps = runMapTasks(shards, workers, args);
  const double map_s = secondsSince(t0);
  for (std::size_t k = 0; k < maps.size(); ++k)
    if (maps[k].code != 0) return 1;
  const auto t1 = std::chrono::steady_clock::now();
  RunReport report;
  const int code = runReduce(profile, front, count, args, &report);
  const double reduce_s = secondsSince(t1);

  nlohmann::json j;
  j["profile"] = profile.name;
  j["workers"] = workers;
  j["overlap_frames"] = args.overlap;
  j["map_wall_s"] = map_s;
  j["reduce_wall_s"] = reduce_s;
  j["total_wall_s"] = map_s + reduce_s;
  for (std::size_t k = 0; k < shards.size(); ++k)
    j["shards"].push_back({{"first_frame", shards[k].first},
                           {"last_frame", shards[k].last},
                           {"wall_s", maps[k].wall_s}});
  io::AtomicFile file(fs::path(args.run.out) / "batch.json");
  file.stream() << j.dump(2) << "\n";
  file.commit();
  std::cerr << "batch: map " << std::fixed << std::setprecision(1) << map_s << " s, reduce "
            << reduce_s << " s; " << (fs::path(args.run.out) / "batch.json").string() << "\n";
  return code;
}

}  // namespace

void addBatchCommand(CLI::App& app, int& result) {
  auto* cmd = app.add_subcommand(
      "batch",
      "reprocess a recorded RGB-D sequence as parallel map tasks (shards of frames through the "
      "profile's front end) and one reduce (the rest of the profile over the joined keyframes)");
  auto args = std::make_shared<BatchArgs>();
  cmd->add_option("profile", args->profile, "profile with an rgbd_player and an rgbd_front_end")
      ->required();
  cmd->add_option("--out", args->run.out, "output folder (required): shard_K/ and the results")
      ->required();
  cmd->add_option("--workers", args->workers,
                  "map tasks at once, each a process (default: one per core)")
      ->check(CLI::Range(1, 256));
  cmd->add_option("--shards", args->shards, "shards the sequence is cut into (default: workers)")
      ->check(CLI::Range(1, 4096));
  cmd->add_option("--overlap", args->overlap, "frames each shard shares with the next (5)");
  cmd->add_option("--shard", args->shard,
                  "run map task K alone into OUT/shard_K (another host's share of the work)")
      ->check(CLI::Range(0, 4095));
  cmd->add_flag("--reduce", args->reduce_only,
                "run the reduce alone over OUT/shard_0 .. shard_{S-1} (with --shards S)");
  cmd->add_option("--set", args->run.sets, "override: ACTOR.KEY=VALUE, KEY=VALUE (repeatable)");
  cmd->add_option("--threads", args->run.threads, "executor threads per process (0: all cores)");
  cmd->add_flag("--quiet", args->run.quiet, "no progress line and no metrics table");
  cmd->callback([args, &result] { result = runBatch(*args); });
}

}  // namespace tessera::app
