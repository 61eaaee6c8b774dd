// McapWriter: writes MCAP files (format version 0, docs/viewer.md#mcap), the container Foxglove
// and other robotics tools open: schemas, channels (a topic each) and timestamped messages.
//
// Layout written: magic, Header, the data section (each schema and channel record as it is
// added, then chunks of messages, each followed by its message indexes), DataEnd, the summary
// (schemas, channels, statistics, chunk indexes), summary offsets, Footer, magic. Chunks hold
// at most chunk_bytes of records before compression (zstd or none), so readers seek by time
// through the chunk indexes. Chunks and the summary carry CRCs (zlib's crc32); the data
// section's is left 0 ("not available").
//
// Times are nanoseconds (the recording's stamps). Not thread-safe; the writer owns its file
// until close() or destruction. Errors (the file cannot be written, a message names an unknown
// channel, more than 65535 schemas or channels) throw McapError naming the file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <map>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera::viewer {

class McapError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct McapWriterOptions {
  enum class Compression { kNone, kZstd };
  Compression compression = Compression::kZstd;
  std::size_t chunk_bytes = std::size_t{1} << 20;  ///< uncompressed records per chunk
  std::string profile;                             ///< Header.profile ("" or e.g. "ros2")
  std::string library = "tessera";                 ///< Header.library
};

class McapWriter {
 public:
  /// Creates (truncates) partialPath() and writes the magic and the header; close() renames it
  /// to `path`, so `path` is only ever a whole file.
  explicit McapWriter(std::string path, McapWriterOptions options = {});
  ~McapWriter();  ///< closes if close() was not called; errors are swallowed
  /// Where the file is written until close(): path + ".partial".
  std::string partialPath() const { return path_ + ".partial"; }
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  /// A schema (name e.g. "foxglove.Grid", encoding e.g. "jsonschema"); returns its id (>= 1).
  std::uint16_t addSchema(const std::string& name, const std::string& encoding,
                          const std::string& data);
  /// A channel on `topic` whose messages use `message_encoding` ("json", …); schema_id 0: none.
  std::uint16_t addChannel(std::uint16_t schema_id, const std::string& topic,
                           const std::string& message_encoding,
                           const std::map<std::string, std::string>& metadata = {});
  /// One message; log_time and publish_time in ns. Messages may come in any time order.
  void write(std::uint16_t channel, std::uint64_t log_time, std::uint64_t publish_time,
             std::span<const std::uint8_t> data);
  void write(std::uint16_t channel, std::uint64_t log_time, const std::string& data);

  /// Writes the last chunk, the summary and the footer, and closes the file.
  void close();

  struct Stats {
    std::uint64_t messages = 0, chunks = 0, file_bytes = 0;
  };
  const Stats& stats() const { return stats_; }

 private:
  void flushChunk();
  void emit(const std::vector<std::uint8_t>& bytes);  ///< to the file, counted in the data CRC

  std::string path_;
  McapWriterOptions options_;
  std::FILE* file_ = nullptr;
  std::uint64_t offset_ = 0;                      ///< bytes written so far
  std::vector<std::uint8_t> schemas_, channels_;  ///< their records again, for the summary
  std::uint16_t schema_count_ = 0, channel_count_ = 0;
  // The open chunk: its records, time range and per-channel (time, offset) index.
  std::vector<std::uint8_t> chunk_;
  std::uint64_t chunk_start_ = 0, chunk_end_ = 0;
  std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> chunk_index_;
  std::vector<std::uint8_t> chunk_indexes_;  ///< ChunkIndex records for the summary
  std::map<std::uint16_t, std::uint64_t> channel_counts_;
  std::map<std::uint16_t, std::uint32_t> sequence_;
  std::uint64_t first_time_ = 0, last_time_ = 0;
  Stats stats_;
};

}  // namespace tessera::viewer
