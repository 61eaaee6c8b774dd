#include <tessera/players/recording_actors.hpp>

#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>

namespace tessera::players {

namespace fs = std::filesystem;

// ---------------------------------------------------------------- recorder

RecorderActor::RecorderActor(RecorderOptions options) : options_(std::move(options)) {
  auto fail = [](const std::string& key, const std::string& what) {
    throw ConfigError("recorder: option '" + key + "': " + what);
  };
  if (options_.path.empty()) fail("path", "is required");
  if (options_.topics.empty())
    fail("topics", "is required: the topics to record, e.g. [scan, odom]");
  if (options_.compression != "none" && options_.compression != "zstd")
    fail("compression", "must be none or zstd, got '" + options_.compression + "'");
  if (options_.zstd_level < 1 || options_.zstd_level > 19) fail("zstd_level", "must be 1..19");
  if (options_.block_kib < 1 || options_.block_kib > 512 * 1024)
    fail("block_kib", "must be in 1..524288");
  if (options_.queue < 1) fail("queue", "must be >= 1");
  for (std::size_t i = 0; i < options_.topics.size(); ++i) {
    for (std::size_t j = 0; j < i; ++j)
      if (options_.topics[i] == options_.topics[j])
        fail("topics", "lists '" + options_.topics[i] + "' twice");
  }
}

void RecorderActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  path_ = options_.path;
  if (fs::path(path_).is_relative() && !ctx.outputDir().empty())
    path_ = (fs::path(ctx.outputDir()) / path_).string();
  for (std::size_t i = 0; i < options_.topics.size(); ++i) {
    ctx.subscribeUntyped(options_.topics[i], kAnyMessageType,
                         MailboxPolicy::reliable(static_cast<std::size_t>(options_.queue)),
                         [this, i](const std::shared_ptr<const MessageStorage>& m) {
                           record(static_cast<std::uint32_t>(i), *m);
                         });
  }
}

void RecorderActor::start() {
  // Topic types are known once every actor is configured, so the file is created here.
  std::vector<RecordingTopic> topics;
  for (const auto& t : options_.topics) {
    const MessageType type = ctx_->topicType(t);
    topics.push_back({t, type.id, type.name});
  }
  RecordingWriterOptions w;
  w.compression = options_.compression == "zstd" ? RecordingWriterOptions::Compression::kZstd
                                                 : RecordingWriterOptions::Compression::kNone;
  w.zstd_level = options_.zstd_level;
  w.block_bytes = static_cast<std::size_t>(options_.block_kib) * 1024;
  try {
    writer_ = std::make_unique<RecordingWriter>(path_, std::move(topics), w);
  } catch (const std::exception& e) {
    fail(e.what());
  }
  last_flush_ = steadyNow();
}

void RecorderActor::record(std::uint32_t topic, const MessageStorage& message) {
  if (!writer_) return;
  const Nanos t0 = steadyNow();
  try {
    writer_->append(topic, ctx_->now(), message);
    // Bounded loss on a crash without a timer (a timer would add stops to a simulated clock).
    if (t0 - last_flush_ > kNanosPerSecond) {
      writer_->flush();
      last_flush_ = t0;
    }
  } catch (const std::exception& e) {
    fail(e.what());
  }
  busy_ns_ += steadyNow() - t0;
}

void RecorderActor::fail(const std::string& error) {
  error_ = error;
  if (writer_) final_stats_ = writer_->stats();
  writer_.reset();
  ctx_->requestStop("recorder: " + error);
}

void RecorderActor::stop() {
  if (!writer_) return;
  const Nanos t0 = steadyNow();
  try {
    writer_->close();
    final_stats_ = writer_->stats();
    writer_.reset();
  } catch (const std::exception& e) {
    error_ = e.what();
  }
  busy_ns_ += steadyNow() - t0;
}

void RecorderActor::summarize(Summary& out) const {
  const auto& s = writer_ ? writer_->stats() : final_stats_;
  out["path"] = path_;
  out["messages"] = static_cast<std::int64_t>(s.messages);
  out["blocks"] = static_cast<std::int64_t>(s.blocks);
  out["payload_mb"] = static_cast<double>(s.payload_bytes) / 1e6;
  out["file_mb"] = static_cast<double>(s.file_bytes) / 1e6;
  out["compression_ratio"] =
      s.file_bytes > 0 ? static_cast<double>(s.payload_bytes) / static_cast<double>(s.file_bytes)
                       : 0.0;
  out["write_mb_per_s"] =
      busy_ns_ > 0 ? static_cast<double>(s.payload_bytes) / 1e6 / nanosToSeconds(busy_ns_) : 0.0;
  out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("recorder", RecorderActor, RecorderOptions,
                       "records topics of any type to a recording file (tessera record)");

// ---------------------------------------------------------------- player

RecordingPlayer::RecordingPlayer(RecordingPlayerOptions options) : options_(std::move(options)) {
  if (options_.path.empty())
    throw ConfigError("recording_player: option 'path': is required: the recording to replay");
  if (!(options_.start_time >= 0) || !std::isfinite(options_.start_time))
    throw ConfigError("recording_player: option 'start_time': must be >= 0");
  RecordingReaderOptions r;
  r.topics = options_.topics;
  try {
    reader_ = std::make_unique<RecordingReader>(options_.path, r);
  } catch (const RecordingError& e) {
    throw ConfigError(std::string("recording_player: ") + e.what());
  }
  if (options_.start_time > 0)
    reader_->seek(reader_->firstStamp() + secondsToNanos(options_.start_time));
}

void RecordingPlayer::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.declareFiniteSource();
  const auto& topics = reader_->topics();
  publishers_.resize(topics.size());
  for (std::size_t i = 0; i < topics.size(); ++i) {
    const auto& t = topics[i];
    const bool wanted =
        options_.topics.empty() ||
        std::find(options_.topics.begin(), options_.topics.end(), t.name) != options_.topics.end();
    if (!wanted) continue;
    // The reader outlives the runtime's use of the name (this actor lives as long as it).
    publishers_[i] = ctx.advertiseUntyped(t.name, MessageType{t.type_id, t.type_name.c_str()});
    total_ += reader_->indexed() ? reader_->topicCounts()[i] : 0;
  }
  if (total_ == 0) total_ = reader_->messageCount();
  ctx.callAt(ctx.now(), [this] { step(); });
}

void RecordingPlayer::step() {
  if (done_) return;
  const auto next_step = replay_.advance(
      ctx_->now(),
      [this] {
        Pending p;
        if (!reader_->next(p.message)) return false;
        p.stamp = p.message.stamp;
        replay_.next = std::move(p);
        return true;
      },
      [this](const Pending& p) {
        publishers_[p.message.topic].publish(p.message.message);
        if (!first_stamp_) first_stamp_ = p.stamp;
        last_stamp_ = p.stamp;
        ++published_;
      },
      [] { return false; });
  // Losses are reported as the reader meets them, so a long replay shows damage early.
  const auto& losses = reader_->losses();
  for (; losses_reported_ < losses.size(); ++losses_reported_)
    std::cerr << "recording_player: " << reader_->path()
              << ": damaged: " << losses[losses_reported_].describe() << "\n";
  if (!next_step) return finish();
  if (total_ > 0)
    ctx_->reportProgress(static_cast<double>(published_) / static_cast<double>(total_));
  ctx_->callAt(*next_step, [this] { step(); });
}

void RecordingPlayer::finish() {
  if (done_) return;
  done_ = true;
  replay_.next.reset();
  ctx_->reportProgress(1.0);
  ctx_->finished();
}

void RecordingPlayer::summarize(Summary& out) const {
  out["messages_published"] = static_cast<std::int64_t>(published_);
  out["indexed"] = std::int64_t{reader_->indexed() ? 1 : 0};
  const auto& losses = reader_->losses();
  out["losses"] = static_cast<std::int64_t>(losses.size());
  std::int64_t lost = 0;
  std::string report;
  for (const auto& l : losses) {
    lost += static_cast<std::int64_t>(l.messages.value_or(0));
    if (!report.empty()) report += '\n';
    report += l.describe();
  }
  out["messages_lost"] = lost;
  out["loss_report"] = report;
  out["first_stamp_s"] = first_stamp_ ? nanosToSeconds(*first_stamp_) : 0.0;
  out["last_stamp_s"] = last_stamp_ ? nanosToSeconds(*last_stamp_) : 0.0;
}

TESSERA_REGISTER_ACTOR("recording_player", RecordingPlayer, RecordingPlayerOptions,
                       "replays a recording (tessera record) on its topics, byte for byte");

}  // namespace tessera::players
