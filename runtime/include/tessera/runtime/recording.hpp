// Recordings: files of Cap'n Proto messages with topic, type and timestamp (format version 1,
// described byte by byte in docs/recording_format.md).
//
// RecordingWriter appends messages in Cap'n Proto's standard framing (the same bytes a
// subscriber reads), grouped into checksummed blocks that may be zstd-compressed; close() adds an
// index of the blocks (offsets, time ranges, counts) and a footer pointing to it.
//
// RecordingReader opens a file, reads its topic table, and iterates its messages in file order.
// It uses the index when the footer is intact, else scans the blocks one after the other. A
// damaged block (bad checksum, impossible length, truncated) costs only its own messages: the
// reader resynchronises on the next valid block header and records a RecordingLoss naming the
// byte offset, the byte count and, when known, the number of messages lost. Only an unreadable
// file header (not a recording, unknown version, corrupted topic table) is an error.
//
// Times: stamps are int64 ns on the runtime clock of the recording process (the simulated clock
// in simulation, so replays are deterministic). Ownership: the writer owns its file until
// close() or destruction; messages returned by the reader are independent shared storages.
#pragma once

#include <tessera/messages/message.hpp>
#include <tessera/runtime/clock.hpp>

#include <cstdint>
#include <cstdio>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera {

/// A file that cannot be read as a recording (or written). The message names the file, the byte
/// offset and what was expected.
class RecordingError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

inline constexpr std::uint32_t kRecordingFormatVersion = 1;

/// One entry of a recording's topic table.
struct RecordingTopic {
  std::string name;       ///< global topic name
  std::uint64_t type_id;  ///< Cap'n Proto schema id of the message type (0: unknown)
  std::string type_name;  ///< readable type name, for errors and --info
};

struct RecordingWriterOptions {
  enum class Compression { kNone, kZstd };
  Compression compression = Compression::kNone;
  int zstd_level = 1;  ///< sensor floats: level 3 is ~2.5x slower for ~2% smaller files
  /// A block is written once its uncompressed payload reaches this many bytes (a single larger
  /// message makes a block of its own). Smaller blocks lose less on damage and seek finer.
  std::size_t block_bytes = std::size_t{1} << 20;
};

/// Writes a recording. Not thread-safe (one recorder actor owns it).
class RecordingWriter {
 public:
  /// Creates (truncates) partialPath() and writes the file header; close() renames it to `path`.
  /// Throws RecordingError.
  RecordingWriter(std::string path, std::vector<RecordingTopic> topics,
                  RecordingWriterOptions options = {});
  /// Closes the file if close() was not called; errors are swallowed (call close() to see them).
  ~RecordingWriter();
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;

  /// Index of `name` in the topic table; throws RecordingError if it is not in it.
  std::uint32_t topicIndex(const std::string& name) const;
  /// Appends one message of topic `topic` (an index into the topic table) stamped `stamp`.
  void append(std::uint32_t topic, Nanos stamp, const MessageStorage& message);
  /// Writes the pending block (if any) and flushes it to the OS, so a crash loses nothing
  /// appended before.
  void flush();
  /// Writes the pending block, the index and the footer, and closes the file.
  void close();

  struct Stats {
    std::uint64_t messages = 0;
    std::uint64_t blocks = 0;
    std::uint64_t payload_bytes = 0;  ///< message records before compression
    std::uint64_t file_bytes = 0;     ///< bytes written to the file so far
  };
  const Stats& stats() const { return stats_; }
  const std::string& path() const { return path_; }
  /// Where the file is written until close() renames it to path(): path() + ".partial".
  std::string partialPath() const { return path_ + ".partial"; }

 private:
  void writeBlock();
  void writeBytes(const void* data, std::size_t size);

  std::string path_;
  std::vector<RecordingTopic> topics_;
  RecordingWriterOptions options_;
  std::FILE* file_ = nullptr;
  std::vector<unsigned char> block_;   // pending uncompressed records
  std::vector<unsigned char> packed_;  // compression output, reused
  std::uint32_t block_messages_ = 0;
  Nanos block_first_ = 0, block_last_ = 0;
  struct IndexEntry {
    std::uint64_t offset;
    std::uint32_t messages;
    Nanos first, last;
  };
  std::vector<IndexEntry> index_;
  std::vector<std::uint64_t> topic_counts_;
  Stats stats_;
};

/// Damage found while reading: `bytes` bytes from `offset` were skipped.
struct RecordingLoss {
  std::uint64_t offset = 0;
  std::uint64_t bytes = 0;
  std::optional<std::uint64_t> messages;  ///< messages lost, when a header or the index says
  std::string what;                       ///< what was expected and what was found
  std::string describe() const;           ///< one line: offset, bytes, messages, what
};

/// One message read back.
struct RecordedMessage {
  std::uint32_t topic = 0;  ///< index into RecordingReader::topics()
  Nanos stamp = 0;
  std::shared_ptr<const MessageStorage> message;
};

struct RecordingReaderOptions {
  /// Only messages of these topics are decoded and returned (empty: all).
  std::vector<std::string> topics;
  DecodeLimits limits;
};

class RecordingReader {
 public:
  /// Opens a file. Throws RecordingError when it is not a recording, has an unknown format
  /// version or a damaged file header; later damage becomes losses(), never an exception.
  explicit RecordingReader(const std::string& path, RecordingReaderOptions options = {});
  /// Reads a recording held in memory (`name` names it in messages; used by the fuzzer).
  static RecordingReader fromBytes(std::string name, std::vector<unsigned char> bytes,
                                   RecordingReaderOptions options = {});
  ~RecordingReader();
  RecordingReader(RecordingReader&&) noexcept;
  RecordingReader& operator=(RecordingReader&&) noexcept;

  const std::string& path() const;
  std::uint32_t version() const;
  const std::vector<RecordingTopic>& topics() const;
  /// True when the file was closed properly and its index was used; false when it was scanned.
  bool indexed() const;
  /// From the index or the scanned block headers (damaged blocks excluded).
  std::uint64_t blockCount() const;
  std::uint64_t messageCount() const;
  /// Per topic (same order as topics()); from the index, else counted while reading.
  const std::vector<std::uint64_t>& topicCounts() const;
  Nanos firstStamp() const;
  Nanos lastStamp() const;

  /// The next intact message of a selected topic, in file order; false at the end.
  bool next(RecordedMessage& out);
  /// Continues from the first block that may hold messages stamped >= t; next() then skips
  /// earlier messages of that block.
  void seek(Nanos t);
  /// Damage met so far (file-level damage is known after opening; block damage after next()
  /// reached the block).
  const std::vector<RecordingLoss>& losses() const;

  struct Impl;

 private:
  explicit RecordingReader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tessera
