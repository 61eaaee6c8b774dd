#include <tessera/viewer/mcap_recorder_actor.hpp>

#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/viewer/foxglove_json.hpp>
#include <tessera/viewer/foxglove_mcap.hpp>

#include <algorithm>
#include <filesystem>
#include <iostream>

namespace tessera::viewer {

namespace fs = std::filesystem;

McapRecorderActor::McapRecorderActor(McapRecorderOptions options) : options_(std::move(options)) {
  auto fail = [](const std::string& key, const std::string& what) {
    throw ConfigError("mcap_recorder: option '" + key + "': " + what);
  };
  if (options_.path.empty()) fail("path", "is required");
  if (options_.topics.empty())
    fail("topics", "is required: the topics to record, e.g. [scan, odom]");
  if (options_.compression != "none" && options_.compression != "zstd")
    fail("compression", "must be none or zstd, got '" + options_.compression + "'");
  if (options_.chunk_kib < 1 || options_.chunk_kib > 512 * 1024)
    fail("chunk_kib", "must be in 1..524288");
  if (options_.queue < 1) fail("queue", "must be >= 1");
  for (std::size_t i = 0; i < options_.topics.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (options_.topics[i] == options_.topics[j])
        fail("topics", "lists '" + options_.topics[i] + "' twice");
}

void McapRecorderActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  path_ = options_.path;
  if (fs::path(path_).is_relative() && !ctx.outputDir().empty())
    path_ = (fs::path(ctx.outputDir()) / path_).string();
  for (std::size_t i = 0; i < options_.topics.size(); ++i)
    ctx.subscribeUntyped(
        options_.topics[i], kAnyMessageType,
        MailboxPolicy::reliable(static_cast<std::size_t>(options_.queue)),
        [this, i](const std::shared_ptr<const MessageStorage>& m) { record(i, *m); });
}

void McapRecorderActor::start() {
  // Types are known once every actor is configured: check them before creating the file.
  std::vector<MessageType> types;
  for (const auto& t : options_.topics) {
    types.push_back(ctx_->topicType(t));
    if (!knownMessageType(types.back().id))
      throw ConfigError("mcap_recorder: topic '" + t + "' has type " + types.back().name +
                        ", which has no Foxglove form in this build");
  }
  McapWriterOptions o;
  o.compression = options_.compression == "zstd" ? McapWriterOptions::Compression::kZstd
                                                 : McapWriterOptions::Compression::kNone;
  o.chunk_bytes = static_cast<std::size_t>(options_.chunk_kib) * 1024;
  try {
    writer_ = std::make_unique<McapWriter>(path_, o);
    foxglove_ = std::make_unique<FoxgloveMcap>(*writer_);
    for (std::size_t i = 0; i < options_.topics.size(); ++i)
      channels_.push_back(foxglove_->addTopic(options_.topics[i], types[i].id, types[i].name));
  } catch (const McapError& e) {
    error_ = e.what();
    foxglove_.reset();
    writer_.reset();
    ctx_->requestStop(std::string("mcap_recorder: ") + e.what());
  }
}

void McapRecorderActor::record(std::size_t topic, const MessageStorage& message) {
  if (!writer_) return;
  try {
    foxglove_->write(channels_[topic], static_cast<std::uint64_t>(std::max<Nanos>(ctx_->now(), 0)),
                     message);
  } catch (const MessageError& e) {
    if (++unreadable_ <= 5) std::cerr << "[" << ctx_->name() << "] " << e.what() << "; skipped\n";
  } catch (const McapError& e) {
    error_ = e.what();
    final_stats_ = writer_->stats();
    foxglove_.reset();
    writer_.reset();
    ctx_->requestStop(std::string("mcap_recorder: ") + e.what());
  }
}

void McapRecorderActor::stop() {
  if (!writer_) return;
  try {
    writer_->close();
  } catch (const McapError& e) {
    error_ = e.what();
  }
  final_stats_ = writer_->stats();
  foxglove_.reset();
  writer_.reset();
}

void McapRecorderActor::summarize(Summary& out) const {
  const auto& s = writer_ ? writer_->stats() : final_stats_;
  out["path"] = path_;
  out["messages"] = static_cast<std::int64_t>(s.messages);
  out["chunks"] = static_cast<std::int64_t>(s.chunks);
  out["file_mb"] = static_cast<double>(s.file_bytes) / 1e6;
  out["unreadable"] = static_cast<std::int64_t>(unreadable_);
  out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("mcap_recorder", McapRecorderActor, McapRecorderOptions,
                       "records topics into an MCAP file in Foxglove's schemas (tessera record "
                       "--out F.mcap)");

}  // namespace tessera::viewer
