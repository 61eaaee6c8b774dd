// tessera record / tessera replay: a profile run with a recorder actor added, and a recording
// published again into a profile (or checked with --info, or exported to MCAP with --export).
// Format: docs/recording_format.md.
#include "cli_inputs.hpp"
#include "commands.hpp"

#include <tessera/runtime/recording.hpp>
#include <tessera/viewer/foxglove_json.hpp>
#include <tessera/viewer/foxglove_mcap.hpp>
#include <tessera/viewer/mcap_writer.hpp>

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <optional>
#include <set>
#include <sstream>

namespace tessera::app {

namespace fs = std::filesystem;

namespace {

// Exit code of a replay or --info that finished but met damage in the file.
constexpr int kDamagedExit = 3;

std::vector<std::string> splitTopics(const std::vector<std::string>& args) {
  std::vector<std::string> out;
  for (const auto& a : args) {
    std::size_t start = 0;
    while (start <= a.size()) {
      const auto comma = a.find(',', start);
      const auto part =
          a.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
      if (!part.empty()) out.push_back(part);
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
  }
  return out;
}

const Summary* summaryOf(const RunReport& report, const std::string& actor) {
  for (const auto& a : report.actors)
    if (a.name == actor) return &a.summary;
  return nullptr;
}

template <typename T>
T summaryValue(const Summary& s, const std::string& key) {
  auto it = s.find(key);
  if (it == s.end() || !std::holds_alternative<T>(it->second)) return T{};
  return std::get<T>(it->second);
}

void printTopicList(const std::vector<std::string>& topics, std::ostream& os) {
  for (std::size_t i = 0; i < topics.size(); ++i) os << (i ? ", " : "") << topics[i];
}

// Removes the actors that publish a replayed topic, then, repeatedly, those that subscribe to a
// topic nothing publishes any more (e.g. an odometry writer when odometry was not recorded).
void replaceRecordedSources(Profile& profile, const std::vector<std::string>& replayed) {
  RuntimeOptions options;
  options.show_progress = false;
  options.threads = 1;
  auto wiring = buildRuntime(profile, options);  // configured, never started
  const std::set<std::string> replayed_set(replayed.begin(), replayed.end());
  std::vector<ActorSpec> kept;
  for (const auto& a : profile.actors) {
    std::vector<std::string> clash;
    for (const auto& t : wiring->publicationsOf(a.name))
      if (replayed_set.count(t)) clash.push_back(t);
    if (clash.empty()) {
      kept.push_back(a);
      continue;
    }
    std::cerr << "replay: not running '" << a.name << "' (it publishes ";
    printTopicList(clash, std::cerr);
    std::cerr << ", which the recording provides)\n";
  }
  for (bool changed = true; changed;) {
    changed = false;
    std::set<std::string> published = replayed_set;
    for (const auto& a : kept)
      for (const auto& t : wiring->publicationsOf(a.name)) published.insert(t);
    for (auto it = kept.begin(); it != kept.end(); ++it) {
      std::vector<std::string> missing;
      for (const auto& t : wiring->subscriptionsOf(it->name))
        if (!published.count(t)) missing.push_back(t);
      if (missing.empty()) continue;
      std::cerr << "replay: not running '" << it->name << "' (it needs ";
      printTopicList(missing, std::cerr);
      std::cerr << ", which is neither recorded nor published)\n";
      kept.erase(it);
      changed = true;
      break;
    }
  }
  profile.actors = std::move(kept);
}

int printInfo(const std::string& file, const std::vector<std::string>& topics) {
  RecordingReaderOptions options;
  options.topics = topics;
  RecordingReader reader(file, options);
  // Reading every message checks every block and counts what an unindexed file holds.
  RecordedMessage m;
  std::uint64_t read = 0, bytes = 0;
  while (reader.next(m)) {
    ++read;
    bytes += m.message->sizeInBytes();
  }
  std::cout << "recording " << file << "\n"
            << "  format version " << reader.version() << ", " << reader.blockCount() << " blocks, "
            << (reader.indexed() ? "indexed" : "no index (not closed: scanned block by block)")
            << "\n"
            << std::fixed << std::setprecision(3) << "  duration "
            << nanosToSeconds(reader.lastStamp() - reader.firstStamp()) << " s (stamps "
            << nanosToSeconds(reader.firstStamp()) << " .. " << nanosToSeconds(reader.lastStamp())
            << " s), " << read << " intact messages read, " << std::setprecision(2)
            << static_cast<double>(bytes) / 1e6 << " MB of messages, file "
            << static_cast<double>(fs::file_size(file)) / 1e6 << " MB\n";
  const auto& counts = reader.topicCounts();
  for (std::size_t i = 0; i < reader.topics().size(); ++i) {
    const auto& t = reader.topics()[i];
    std::cout << "  topic " << std::left << std::setw(24) << t.name << std::setw(20) << t.type_name
              << std::right << std::setw(10) << counts[i] << " messages  (type id 0x" << std::hex
              << t.type_id << std::dec << ")\n";
  }
  const auto& losses = reader.losses();
  if (losses.empty()) {
    std::cout << "  no damage found\n";
    return 0;
  }
  std::cout << "  DAMAGED: " << losses.size() << " damaged region(s):\n";
  for (const auto& l : losses) std::cout << "    " << l.describe() << "\n";
  return kDamagedExit;
}

}  // namespace

void addRecordCommand(CLI::App& app, int& result) {
  auto* cmd = app.add_subcommand("record", "run a profile and record topics to a file");
  struct Args {
    std::string profile, file, compression = "zstd";
    std::vector<std::string> topics;
    std::int64_t block_kib = 1024;
    int zstd_level = 1;
    double rate = -1;
    RunSettings run;
  };
  auto args = std::make_shared<Args>();
  cmd->add_option("profile", args->profile, "profile name (apps/profiles/NAME.yaml) or path")
      ->required();
  cmd->add_option("--topics", args->topics, "topics to record: a,b,c (global names)")
      ->required()
      ->allow_extra_args(false);
  cmd->add_option("--out", args->file,
                  "recording file to write (e.g. run.trec; run.mcap writes MCAP for Foxglove)")
      ->required();
  cmd->add_option("--dir", args->run.out, "output folder for the profile's other outputs");
  cmd->add_option("--compression", args->compression, "none | zstd")
      ->check(CLI::IsMember({"none", "zstd"}));
  cmd->add_option("--block-kib", args->block_kib,
                  "uncompressed block size [KiB] (MCAP: chunk size)");
  cmd->add_option("--zstd-level", args->zstd_level, "zstd level 1..19");
  cmd->add_option("--rate", args->rate, "simulated clock pace: 0 as fast as possible, 1 real time");
  addRunOptions(*cmd, args->run);
  cmd->callback([args, &result] {
    const std::string path = resolveProfilePath(args->profile, profileSearchDirs());
    Profile profile = loadProfile(path, args->run.sets);
    if (args->rate >= 0) profile.sim_rate = args->rate;
    applyViewOptions(profile, args->run, args->rate >= 0);
    const auto topics = splitTopics(args->topics);
    // A .mcap file gets the MCAP recorder (Foxglove's schemas), anything else a recording.
    const bool mcap = fs::path(args->file).extension() == ".mcap";
    YAML::Node params;
    params["path"] = fs::absolute(args->file).lexically_normal().string();
    for (const auto& t : topics) params["topics"].push_back(t);
    params["compression"] = args->compression;
    params[mcap ? "chunk_kib" : "block_kib"] = args->block_kib;
    if (!mcap) params["zstd_level"] = args->zstd_level;
    const std::string name = uniqueActorName(profile, mcap ? "mcap_recorder" : "recorder");
    profile.actors.push_back(actorSpec(name, mcap ? "mcap_recorder" : "recorder", params));
    RunReport report;
    result = runProfile(profile, "record", args->run, &report);
    if (const Summary* s = summaryOf(report, name)) {
      const auto error = summaryValue<std::string>(*s, "error");
      if (!error.empty()) {
        std::cerr << "error: recorder: " << error << "\n";
        result = 1;
      }
      if (mcap) {
        std::cerr << std::fixed << std::setprecision(2) << "recorded "
                  << summaryValue<std::int64_t>(*s, "messages") << " messages in "
                  << summaryValue<std::int64_t>(*s, "chunks") << " chunks to "
                  << summaryValue<std::string>(*s, "path") << " (MCAP, "
                  << summaryValue<double>(*s, "file_mb") << " MB)\n";
        return;
      }
      std::cerr << std::fixed << std::setprecision(2) << "recorded "
                << summaryValue<std::int64_t>(*s, "messages") << " messages in "
                << summaryValue<std::int64_t>(*s, "blocks") << " blocks to "
                << summaryValue<std::string>(*s, "path") << ": "
                << summaryValue<double>(*s, "payload_mb") << " MB of messages, file "
                << summaryValue<double>(*s, "file_mb") << " MB (compression " << args->compression
                << ", ratio " << summaryValue<double>(*s, "compression_ratio")
                << "), writer throughput " << std::setprecision(0)
                << summaryValue<double>(*s, "write_mb_per_s") << " MB/s\n";
    }
  });
}

// `replay --export OUT.mcap`: every intact message of the selected topics into an MCAP file,
// in Foxglove's well-known schemas where one fits (docs/viewer.md#mcap).
int exportMcap(const std::string& file, const std::vector<std::string>& topics,
               const std::string& out, bool compress) {
  RecordingReaderOptions options;
  options.topics = topics;
  RecordingReader reader(file, options);
  viewer::McapWriterOptions mo;
  mo.compression = compress ? viewer::McapWriterOptions::Compression::kZstd
                            : viewer::McapWriterOptions::Compression::kNone;
  viewer::McapWriter writer(out, mo);
  // A channel per recorded topic (FoxgloveMcap: schemas per type, a "tf" channel for the frames
  // odometry, scans and map_to_odom imply); a type this build does not define cannot be
  // converted: its topic is named and its messages counted.
  viewer::FoxgloveMcap foxglove(writer);
  std::vector<std::optional<std::size_t>> channel(reader.topics().size());
  for (std::size_t i = 0; i < reader.topics().size(); ++i) {
    const RecordingTopic& t = reader.topics()[i];
    if (!topics.empty() && !std::count(topics.begin(), topics.end(), t.name)) continue;
    if (!viewer::knownMessageType(t.type_id)) {
      std::cerr << "export: topic '" << t.name << "' has type " << t.type_name
                << ", unknown to this build: its messages are not exported\n";
      continue;
    }
    channel[i] = foxglove.addTopic(t.name, t.type_id, t.type_name);
  }
  RecordedMessage m;
  std::uint64_t skipped = 0, malformed = 0;
  while (reader.next(m)) {
    if (!channel[m.topic]) {
      ++skipped;
      continue;
    }
    try {
      foxglove.write(*channel[m.topic], static_cast<std::uint64_t>(std::max<Nanos>(m.stamp, 0)),
                     *m.message);
    } catch (const MessageError& e) {
      if (++malformed <= 5) std::cerr << "export: " << e.what() << "; skipped\n";
    }
  }
  writer.close();
  std::cerr << "exported " << writer.stats().messages - foxglove.transforms() << " messages on "
            << std::count_if(channel.begin(), channel.end(),
                             [](const auto& c) { return c.has_value(); })
            << " topics (and " << foxglove.transforms() << " frame transforms on 'tf') in "
            << writer.stats().chunks << " chunks to " << out << " (" << std::fixed
            << std::setprecision(2) << static_cast<double>(writer.stats().file_bytes) / 1e6
            << " MB)";
  if (skipped > 0) std::cerr << "; " << skipped << " messages of unknown types not exported";
  if (malformed > 0) std::cerr << "; " << malformed << " unreadable messages skipped";
  std::cerr << "\n";
  const auto& losses = reader.losses();
  if (!losses.empty()) {
    std::cerr << "DAMAGED recording: " << losses.size()
              << " damaged region(s); every intact message was exported:\n";
    for (const auto& l : losses) std::cerr << "  " << l.describe() << "\n";
    return kDamagedExit;
  }
  return 0;
}

void addReplayCommand(CLI::App& app, int& result) {
  auto* cmd = app.add_subcommand(
      "replay",
      "publish a recording again (into --profile P), or check it with --info; exit code 3 when "
      "the file is damaged (every intact message is still replayed)");
  struct Args {
    std::string file, profile;
    std::vector<std::string> topics;
    double rate = 0;
    bool max_speed = false, info = false, uncompressed = false;
    double start = 0;
    std::string export_file;
    RunSettings run;
  };
  auto args = std::make_shared<Args>();
  cmd->add_option("file", args->file, "recording (tessera record --out FILE)")->required();
  auto* rate = cmd->add_option("--rate", args->rate, "pace: 1 real time, 2 twice as fast");
  cmd->add_flag("--max-speed", args->max_speed,
                "as fast as the CPU allows on the simulated clock (default; deterministic)")
      ->excludes(rate);
  cmd->add_option("--topics", args->topics, "topics to replay: a,b (default: all)")
      ->allow_extra_args(false);
  cmd->add_option("--profile", args->profile,
                  "run this profile with the recording in place of the actors that publish the "
                  "replayed topics");
  cmd->add_option("--start", args->start, "skip the first S seconds of the recording");
  cmd->add_option("--out", args->run.out, "output folder of the run");
  cmd->add_flag("--info", args->info, "print topics, counts, duration and damage; run nothing");
  auto* export_opt = cmd->add_option(
      "--export", args->export_file,
      "write the recording to an MCAP file (Foxglove schemas: scans, grids, poses, paths; other "
      "types as JSON) instead of replaying it");
  cmd->add_flag("--uncompressed", args->uncompressed,
                "with --export: chunks without zstd compression")
      ->needs(export_opt);
  addRunOptions(*cmd, args->run);
  cmd->callback([args, &result] {
    const auto topics = splitTopics(args->topics);
    if (args->info) {
      result = printInfo(args->file, topics);
      return;
    }
    if (!args->export_file.empty()) {
      result = exportMcap(args->file, topics, args->export_file, !args->uncompressed);
      return;
    }
    RecordingReaderOptions ro;
    ro.topics = topics;
    RecordingReader reader(args->file, ro);  // clear error before anything runs
    std::vector<std::string> replayed;
    for (const auto& t : reader.topics())
      if (topics.empty() || std::count(topics.begin(), topics.end(), t.name))
        replayed.push_back(t.name);

    Profile profile;
    if (!args->profile.empty()) {
      const std::string path = resolveProfilePath(args->profile, profileSearchDirs());
      profile = loadProfile(path, args->run.sets);
      replaceRecordedSources(profile, replayed);
    } else {
      profile.name = "replay";
      profile.path = args->file;
      profile.description = "the recording alone (no --profile: nothing subscribes)";
    }
    profile.clock = ClockKind::kSimulated;
    profile.sim_rate = args->max_speed ? 0.0 : args->rate;
    YAML::Node params;
    params["path"] = args->file;
    for (const auto& t : topics) params["topics"].push_back(t);
    params["start_time"] = args->start;
    const std::string name = uniqueActorName(profile, "replay");
    profile.actors.insert(profile.actors.begin(), actorSpec(name, "recording_player", params));
    RunReport report;
    result = runProfile(profile, "replay", args->run, &report);
    if (const Summary* s = summaryOf(report, name)) {
      std::cerr << "replayed " << summaryValue<std::int64_t>(*s, "messages_published")
                << " messages from " << args->file << "\n";
      const auto losses = summaryValue<std::int64_t>(*s, "losses");
      if (losses > 0) {
        std::cerr << "DAMAGED recording: " << losses << " damaged region(s), "
                  << summaryValue<std::int64_t>(*s, "messages_lost") << " messages known lost:\n";
        std::istringstream lines(summaryValue<std::string>(*s, "loss_report"));
        for (std::string line; std::getline(lines, line);) std::cerr << "  " << line << "\n";
        if (result == 0) result = kDamagedExit;
      }
    }
  });
}

}  // namespace tessera::app
