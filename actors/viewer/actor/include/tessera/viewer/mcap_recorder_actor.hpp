// McapRecorderActor ("mcap_recorder"): records topics straight into an MCAP file in Foxglove's
// forms (foxglove_json.hpp; docs/viewer.md#mcap), so a run opens in Foxglove without an export
// step (`tessera record PROFILE --out RUN.mcap`).
//
// Subscribes to the listed topics whatever their types, with reliable mailboxes (nothing is
// dropped; a slow disk slows the publishers), and writes every message at the runtime time it
// was delivered (with a simulated clock, the time it was published). The file is created in
// start(), once the topics' types are known, and closed with its summary in stop(). A topic
// whose type has no Foxglove form this build knows is a ConfigError at start; a message that
// cannot be read is counted and skipped. A relative `path` is inside the run's output folder.
#pragma once

#include <tessera/runtime/actor.hpp>
#include <tessera/viewer/foxglove_mcap.hpp>
#include <tessera/viewer/mcap_writer.hpp>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace tessera::viewer {

struct McapRecorderOptions {
  std::string path = "recording.mcap";
  std::vector<std::string> topics;
  std::string compression = "zstd";
  std::int64_t chunk_kib = 1024;
  std::int64_t queue = 256;

  template <class V>
  void visit(V& v) {
    v("path", path, "MCAP file to write; relative paths go into the run's output folder");
    v("topics", topics, "topics to record (global names); required");
    v("compression", compression, "chunk compression: none | zstd");
    v("chunk_kib", chunk_kib, "uncompressed chunk size [KiB]: the unit readers seek by");
    v("queue", queue, "reliable mailbox capacity per topic [messages]");
  }
};

class McapRecorderActor final : public Actor {
 public:
  explicit McapRecorderActor(McapRecorderOptions options);  // throws ConfigError
  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  /// messages, chunks, file_mb, unreadable, path, error.
  void summarize(Summary& out) const override;

 private:
  void record(std::size_t topic, const MessageStorage& message);

  McapRecorderOptions options_;
  ActorContext* ctx_ = nullptr;
  std::string path_;
  std::unique_ptr<McapWriter> writer_;
  std::unique_ptr<FoxgloveMcap> foxglove_;  ///< borrows *writer_
  std::vector<std::size_t> channels_;
  McapWriter::Stats final_stats_;
  std::uint64_t unreadable_ = 0;
  std::string error_;
};

}  // namespace tessera::viewer
