// recorder and recording_player: the actors around tessera/runtime/recording.hpp.
//
// recorder: subscribes (reliable mailbox: nothing is dropped, a slow disk slows the publishers)
// to the listed topics whatever their types, and appends every message with the runtime time at
// which it was delivered (with a simulated clock, the time it was published) to a recording.
// The file is flushed to the OS at least once a second of wall time and closed with its index in
// stop(). A relative `path` is inside the run's output folder when it has one.
//
// recording_player: a finite source that publishes a recording's messages again, byte for byte,
// on their recorded topics and types: message k at runtime_start + (t_k - t_0), so a simulated
// clock replays as fast as the CPU allows and deterministically, and sim_rate paces it. Damage
// in the file never stops the replay: intact messages are published and each loss is reported
// on stderr and in the summary (byte offset, bytes, messages lost, what was wrong).
#pragma once

#include <tessera/players/replay.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/recording.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::players {

struct RecorderOptions {
  std::string path = "recording.trec";
  std::vector<std::string> topics;
  std::string compression = "zstd";
  int zstd_level = 1;
  std::int64_t block_kib = 1024;
  std::int64_t queue = 256;

  template <class V>
  void visit(V& v) {
    v("path", path, "recording to write; relative paths go into the run's output folder");
    v("topics", topics, "topics to record (global names); required");
    v("compression", compression, "block compression: none | zstd");
    v("zstd_level", zstd_level,
      "zstd level 1..19 (1: fastest; higher levels gain little on float arrays)");
    v("block_kib", block_kib, "uncompressed block size [KiB]: the unit of damage and seeking");
    v("queue", queue, "reliable mailbox capacity per topic [messages]");
  }
};

class RecorderActor final : public Actor {
 public:
  explicit RecorderActor(RecorderOptions options);  // throws ConfigError
  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  // messages, blocks, payload_mb, file_mb, compression_ratio, write_mb_per_s (payload bytes over
  // the time spent framing, compressing and writing), path, error.
  void summarize(Summary& out) const override;

 private:
  void record(std::uint32_t topic, const MessageStorage& message);
  void fail(const std::string& error);

  RecorderOptions options_;
  ActorContext* ctx_ = nullptr;
  std::string path_;
  std::unique_ptr<RecordingWriter> writer_;
  RecordingWriter::Stats final_stats_;
  Nanos busy_ns_ = 0, last_flush_ = 0;
  std::string error_;
};

struct RecordingPlayerOptions {
  std::string path;
  std::vector<std::string> topics;
  double start_time = 0;

  template <class V>
  void visit(V& v) {
    v("path", path, "recording to replay; required");
    v("topics", topics, "topics to publish (empty: every topic of the recording)");
    v("start_time", start_time, "skip messages earlier than this [s after the first message]");
  }
};

class RecordingPlayer final : public Actor {
 public:
  explicit RecordingPlayer(RecordingPlayerOptions options);  // throws ConfigError
  void configure(ActorContext& ctx) override;
  // messages_published, losses, messages_lost (known counts), loss_report (one line per loss),
  // indexed, first_stamp_s, last_stamp_s.
  void summarize(Summary& out) const override;

 private:
  struct Pending {
    RecordedMessage message;
    Nanos stamp = 0;
  };
  void step();
  void finish();

  RecordingPlayerOptions options_;
  std::unique_ptr<RecordingReader> reader_;
  ActorContext* ctx_ = nullptr;
  std::vector<UntypedPublisher> publishers_;  // by topic index of the recording
  ReplayState<Pending> replay_;
  std::uint64_t published_ = 0, total_ = 0;
  std::size_t losses_reported_ = 0;
  std::optional<Nanos> first_stamp_, last_stamp_;
  bool done_ = false;
};

}  // namespace tessera::players
