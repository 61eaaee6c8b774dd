// Recordings (tessera/runtime/recording.hpp, format in docs/recording_format.md): the block
// layout, the writer and the reader with its damage reporting. Longer than ~600 lines on purpose:
// writer and reader must agree on every byte of the layout, which is defined once above both.
#include <tessera/runtime/recording.hpp>

#include <capnp/serialize.h>
#include <fcntl.h>
#include <kj/io.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <limits>
#include <span>
#include <sstream>

namespace tessera {
namespace {

// ---------------------------------------------------------------- layout (recording_format.md)

constexpr unsigned char kFileMagic[8] = {0x89, 'T', 'S', 'R', '\r', '\n', 0x1a, '\n'};
constexpr std::uint32_t kBlockMagic = 0x4b4c4254;   // "TBLK" in file order
constexpr std::uint32_t kIndexMagic = 0x58444954;   // "TIDX"
constexpr std::uint32_t kFooterMagic = 0x444e4554;  // "TEND"
constexpr std::size_t kFilePreamble = 16;           // magic, version, header body size
constexpr std::size_t kBlockHeader = 56;
constexpr std::size_t kRecordHeader = 16;
constexpr std::size_t kIndexEntry = 32;
constexpr std::size_t kIndexHead = 16;
constexpr std::size_t kFooter = 24;
constexpr std::uint32_t kFlagZstd = 1;
// Sanity bounds: a header claiming more is damaged, not a real recording.
constexpr std::uint64_t kMaxHeaderBody = std::uint64_t{16} << 20;
constexpr std::uint64_t kMaxBlockBytes = std::uint64_t{1} << 30;
constexpr std::uint32_t kMaxTopics = 1u << 16;
constexpr std::uint32_t kMaxName = 4096;

std::uint32_t crc(const void* data, std::size_t n, std::uint32_t seed = 0) {
  // zlib's crc32 takes uInt lengths; blocks stay below 4 GiB (kMaxBlockBytes).
  return static_cast<std::uint32_t>(
      ::crc32(seed, static_cast<const Bytef*>(data), static_cast<uInt>(n)));
}

// Little-endian field access (the format is little-endian; so are the machines we run on, and
// Cap'n Proto's own encoding is too).
template <typename T>
void put(std::vector<unsigned char>& out, T v) {
  static_assert(std::is_trivially_copyable_v<T>);
  const auto* p = reinterpret_cast<const unsigned char*>(&v);
  out.insert(out.end(), p, p + sizeof(T));
}
template <typename T>
T get(const unsigned char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

std::string hexBytes(const unsigned char* p, std::size_t n) {
  static const char* digits = "0123456789abcdef";
  std::string s;
  for (std::size_t i = 0; i < n; ++i) {
    if (i) s += ' ';
    s += digits[p[i] >> 4];
    s += digits[p[i] & 15];
  }
  return s;
}

std::string hex32(std::uint32_t v) {
  std::ostringstream s;
  s << "0x" << std::hex << v;
  return s.str();
}

// A kj::OutputStream appending to a byte vector, so Cap'n Proto writes its standard framing
// straight into the pending block (no intermediate copy).
class AppendStream final : public kj::OutputStream {
 public:
  explicit AppendStream(std::vector<unsigned char>& out) : out_(out) {}
  void write(const void* buffer, size_t size) override {
    const auto* p = static_cast<const unsigned char*>(buffer);
    out_.insert(out_.end(), p, p + size);
  }

 private:
  std::vector<unsigned char>& out_;
};

struct BlockHeader {
  std::uint32_t flags = 0;
  std::uint64_t stored = 0, raw = 0;
  std::uint32_t messages = 0, payload_crc = 0;
  Nanos first = 0, last = 0;
};

void encodeBlockHeader(const BlockHeader& h, std::vector<unsigned char>& out) {
  const std::size_t start = out.size();
  put(out, kBlockMagic);
  put(out, h.flags);
  put(out, h.stored);
  put(out, h.raw);
  put(out, h.messages);
  put(out, h.payload_crc);
  put(out, h.first);
  put(out, h.last);
  put(out, std::uint32_t{0});
  put(out, crc(out.data() + start, kBlockHeader - 4));
}

// Parses a block header; nullopt and `why` when it is not a valid one.
std::optional<BlockHeader> decodeBlockHeader(const unsigned char* p, std::string& why) {
  if (get<std::uint32_t>(p) != kBlockMagic) {
    why = "expected block magic 'TBLK', found " + hexBytes(p, 4);
    return std::nullopt;
  }
  const auto stored_crc = get<std::uint32_t>(p + 52);
  const auto computed = crc(p, kBlockHeader - 4);
  if (stored_crc != computed) {
    why = "block header checksum mismatch (stored " + hex32(stored_crc) + ", computed " +
          hex32(computed) + ")";
    return std::nullopt;
  }
  BlockHeader h;
  h.flags = get<std::uint32_t>(p + 4);
  h.stored = get<std::uint64_t>(p + 8);
  h.raw = get<std::uint64_t>(p + 16);
  h.messages = get<std::uint32_t>(p + 24);
  h.payload_crc = get<std::uint32_t>(p + 28);
  h.first = get<Nanos>(p + 32);
  h.last = get<Nanos>(p + 40);
  if ((h.flags & ~kFlagZstd) != 0) {
    why = "unknown block flags " + hex32(h.flags);
    return std::nullopt;
  }
  if (h.stored > kMaxBlockBytes || h.raw > kMaxBlockBytes ||
      ((h.flags & kFlagZstd) == 0 && h.stored != h.raw) ||
      h.raw < std::uint64_t{h.messages} * kRecordHeader) {
    why = "impossible block sizes (stored " + std::to_string(h.stored) + ", raw " +
          std::to_string(h.raw) + ", " + std::to_string(h.messages) + " messages)";
    return std::nullopt;
  }
  return h;
}

}  // namespace

// ---------------------------------------------------------------- writer

RecordingWriter::RecordingWriter(std::string path, std::vector<RecordingTopic> topics,
                                 RecordingWriterOptions options)
    : path_(std::move(path)), topics_(std::move(topics)), options_(options) {
  if (topics_.size() > kMaxTopics)
    throw RecordingError(path_ + ": more than " + std::to_string(kMaxTopics) + " topics");
  for (const auto& t : topics_) {
    if (t.name.size() > kMaxName || t.type_name.size() > kMaxName)
      throw RecordingError(path_ + ": topic or type name longer than " + std::to_string(kMaxName) +
                           " bytes");
  }
  if (options_.block_bytes == 0) options_.block_bytes = 1;
  // Written under a temporary name and renamed by close(), so `path` is only ever a complete
  // recording (a previous one stays until the new one is whole); after a crash the ".partial"
  // file is still readable: the reader scans its blocks.
  file_ = std::fopen(partialPath().c_str(), "wb");
  if (file_ == nullptr)
    throw RecordingError(partialPath() + ": cannot create: " + std::strerror(errno));
  topic_counts_.assign(topics_.size(), 0);

  std::vector<unsigned char> body;
  put(body, static_cast<std::uint32_t>(topics_.size()));
  for (const auto& t : topics_) {
    put(body, static_cast<std::uint32_t>(t.name.size()));
    body.insert(body.end(), t.name.begin(), t.name.end());
    put(body, t.type_id);
    put(body, static_cast<std::uint32_t>(t.type_name.size()));
    body.insert(body.end(), t.type_name.begin(), t.type_name.end());
  }
  std::vector<unsigned char> head(kFileMagic, kFileMagic + 8);
  put(head, kRecordingFormatVersion);
  put(head, static_cast<std::uint32_t>(body.size()));
  head.insert(head.end(), body.begin(), body.end());
  put(head, crc(head.data() + 8, head.size() - 8));
  writeBytes(head.data(), head.size());
  block_.reserve(options_.block_bytes + 4096);
}

RecordingWriter::~RecordingWriter() {
  try {
    close();
  } catch (...) {
    if (file_ != nullptr) std::fclose(file_);
  }
}

std::uint32_t RecordingWriter::topicIndex(const std::string& name) const {
  for (std::size_t i = 0; i < topics_.size(); ++i)
    if (topics_[i].name == name) return static_cast<std::uint32_t>(i);
  throw RecordingError(path_ + ": topic '" + name + "' is not in the recording's topic table");
}

void RecordingWriter::append(std::uint32_t topic, Nanos stamp, const MessageStorage& message) {
  if (file_ == nullptr) throw RecordingError(path_ + ": append after close()");
  if (topic >= topics_.size())
    throw RecordingError(path_ + ": topic index " + std::to_string(topic) + " out of range");
  const auto segments = message.segments();
  const std::size_t bytes = capnp::computeSerializedSizeInWords(segments) * sizeof(capnp::word);
  if (bytes > kMaxBlockBytes - kRecordHeader)
    throw RecordingError(path_ + ": message of " + std::to_string(bytes) +
                         " bytes is larger than a block may be");
  if (!block_.empty() && block_.size() + kRecordHeader + bytes > options_.block_bytes) writeBlock();
  put(block_, topic);
  put(block_, static_cast<std::uint32_t>(bytes));
  put(block_, stamp);
  AppendStream stream(block_);
  capnp::writeMessage(stream, segments);
  if (block_messages_ == 0) block_first_ = block_last_ = stamp;
  block_first_ = std::min(block_first_, stamp);
  block_last_ = std::max(block_last_, stamp);
  ++block_messages_;
  ++topic_counts_[topic];
  ++stats_.messages;
  stats_.payload_bytes += kRecordHeader + bytes;
  if (block_.size() >= options_.block_bytes) writeBlock();
}

void RecordingWriter::writeBytes(const void* data, std::size_t size) {
  if (size != 0 && std::fwrite(data, 1, size, file_) != size)
    throw RecordingError(path_ + ": write failed at byte " + std::to_string(stats_.file_bytes) +
                         ": " + std::strerror(errno));
  stats_.file_bytes += size;
}

void RecordingWriter::writeBlock() {
  if (block_messages_ == 0) return;
  BlockHeader h;
  h.raw = block_.size();
  h.messages = block_messages_;
  h.first = block_first_;
  h.last = block_last_;
  const unsigned char* payload = block_.data();
  std::size_t stored = block_.size();
  if (options_.compression == RecordingWriterOptions::Compression::kZstd) {
    packed_.resize(ZSTD_compressBound(block_.size()));
    const std::size_t n = ZSTD_compress(packed_.data(), packed_.size(), block_.data(),
                                        block_.size(), options_.zstd_level);
    if (ZSTD_isError(n))
      throw RecordingError(path_ + ": zstd compression failed: " + ZSTD_getErrorName(n));
    // Incompressible payloads are stored raw rather than grown.
    if (n < block_.size()) {
      h.flags = kFlagZstd;
      payload = packed_.data();
      stored = n;
    }
  }
  h.stored = stored;
  h.payload_crc = crc(payload, stored);
  std::vector<unsigned char> head;
  encodeBlockHeader(h, head);
  index_.push_back(IndexEntry{stats_.file_bytes, h.messages, h.first, h.last});
  writeBytes(head.data(), head.size());
  writeBytes(payload, stored);
  ++stats_.blocks;
  block_.clear();
  block_messages_ = 0;
}

void RecordingWriter::flush() {
  if (file_ == nullptr) return;
  writeBlock();
  if (std::fflush(file_) != 0)
    throw RecordingError(path_ + ": flush failed: " + std::strerror(errno));
}

void RecordingWriter::close() {
  if (file_ == nullptr) return;
  writeBlock();
  std::vector<unsigned char> index;
  put(index, kIndexMagic);
  put(index, static_cast<std::uint32_t>(index_.size()));
  put(index, static_cast<std::uint32_t>(topics_.size()));
  put(index, std::uint32_t{0});
  for (const auto& e : index_) {
    put(index, e.offset);
    put(index, e.messages);
    put(index, std::uint32_t{0});
    put(index, e.first);
    put(index, e.last);
  }
  for (auto c : topic_counts_) put(index, c);
  put(index, crc(index.data(), index.size()));
  const std::uint64_t index_offset = stats_.file_bytes;
  std::vector<unsigned char> footer;
  put(footer, kFooterMagic);
  std::vector<unsigned char> pointed;
  put(pointed, index_offset);
  put(pointed, static_cast<std::uint64_t>(index.size()));
  put(footer, crc(pointed.data(), pointed.size()));
  footer.insert(footer.end(), pointed.begin(), pointed.end());
  writeBytes(index.data(), index.size());
  writeBytes(footer.data(), footer.size());
  std::FILE* f = file_;
  file_ = nullptr;
  const bool synced = std::fflush(f) == 0 && ::fsync(::fileno(f)) == 0;
  const int sync_errno = errno;
  if (std::fclose(f) != 0 || !synced)
    throw RecordingError(partialPath() +
                         ": close failed: " + std::strerror(synced ? errno : sync_errno) + " (" +
                         path_ + " was not replaced)");
  if (std::rename(partialPath().c_str(), path_.c_str()) != 0)
    throw RecordingError(partialPath() + ": cannot rename to " + path_ + ": " +
                         std::strerror(errno));
}

// ---------------------------------------------------------------- reader

std::string RecordingLoss::describe() const {
  std::ostringstream s;
  s << "byte " << offset << " (+" << bytes
    << " bytes): " << (messages ? std::to_string(*messages) : std::string("an unknown number of"))
    << " message" << (messages && *messages == 1 ? "" : "s") << " lost: " << what;
  return s.str();
}

namespace {

/// Random-access bytes: a file (pread) or a buffer.
class Source {
 public:
  virtual ~Source() = default;
  virtual std::uint64_t size() const = 0;
  /// Reads exactly n bytes at offset; false if they are not all there.
  virtual bool read(std::uint64_t offset, std::size_t n, unsigned char* out) const = 0;
};

class FileSource final : public Source {
 public:
  explicit FileSource(const std::string& path) : path_(path) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw RecordingError(path + ": cannot open: " + std::strerror(errno));
    struct stat st {};
    if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
      ::close(fd_);
      throw RecordingError(path + ": not a regular file");
    }
    size_ = static_cast<std::uint64_t>(st.st_size);
  }
  ~FileSource() override { ::close(fd_); }
  std::uint64_t size() const override { return size_; }
  bool read(std::uint64_t offset, std::size_t n, unsigned char* out) const override {
    if (offset > size_ || n > size_ - offset) return false;
    std::size_t done = 0;
    while (done < n) {
      const ssize_t r = ::pread(fd_, out + done, n - done, static_cast<off_t>(offset + done));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) return false;
      done += static_cast<std::size_t>(r);
    }
    return true;
  }

 private:
  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
};

class MemorySource final : public Source {
 public:
  explicit MemorySource(std::vector<unsigned char> bytes) : bytes_(std::move(bytes)) {}
  std::uint64_t size() const override { return bytes_.size(); }
  bool read(std::uint64_t offset, std::size_t n, unsigned char* out) const override {
    if (offset > bytes_.size() || n > bytes_.size() - offset) return false;
    if (n) std::memcpy(out, bytes_.data() + offset, n);
    return true;
  }

 private:
  std::vector<unsigned char> bytes_;
};

}  // namespace

struct RecordingReader::Impl {
  std::string path;
  std::unique_ptr<Source> source;
  RecordingReaderOptions options;
  std::uint32_t version = 0;
  std::vector<RecordingTopic> topics;
  std::vector<bool> selected;
  std::uint64_t data_start = 0, data_end = 0;
  bool indexed = false;
  struct Block {
    std::uint64_t offset;
    std::uint64_t messages;
    Nanos first, last;
  };
  std::vector<Block> blocks;
  std::vector<std::uint64_t> topic_counts;
  std::vector<RecordingLoss> losses;

  // Iteration state: the records of the current block, decompressed.
  std::size_t next_block = 0;
  std::vector<unsigned char> stored, raw;
  const unsigned char* payload = nullptr;
  std::size_t payload_size = 0, cursor = 0;
  std::uint64_t block_offset = 0, block_bytes = 0, block_messages = 0, block_seen = 0;
  Nanos skip_before = std::numeric_limits<Nanos>::min();

  std::string at(std::uint64_t offset) const {
    return path + ": byte " + std::to_string(offset) + ": ";
  }

  void readFileHeader() {
    const std::uint64_t size = source->size();
    unsigned char pre[kFilePreamble];
    if (!source->read(0, kFilePreamble, pre)) {
      if (size >= 8 && std::memcmp(pre, kFileMagic, 8) != 0) notRecording(pre, size);
      throw RecordingError(path + ": " + std::to_string(size) +
                           " bytes is too short for a recording header (16 bytes: magic, "
                           "version, header size)");
    }
    if (std::memcmp(pre, kFileMagic, 8) != 0) notRecording(pre, size);
    version = get<std::uint32_t>(pre + 8);
    if (version != kRecordingFormatVersion)
      throw RecordingError(at(8) + "recording format version " + std::to_string(version) +
                           ", this build reads version " + std::to_string(kRecordingFormatVersion));
    const std::uint64_t body = get<std::uint32_t>(pre + 12);
    if (body > kMaxHeaderBody || kFilePreamble + body + 4 > size)
      throw RecordingError(at(12) + "header size " + std::to_string(body) +
                           " does not fit in the file of " + std::to_string(size) +
                           " bytes (truncated or damaged header)");
    std::vector<unsigned char> head(kFilePreamble + body + 4);
    source->read(0, head.size(), head.data());
    const auto stored_crc = get<std::uint32_t>(head.data() + kFilePreamble + body);
    const auto computed = crc(head.data() + 8, kFilePreamble - 8 + body);
    if (stored_crc != computed)
      throw RecordingError(at(kFilePreamble + body) + "file header checksum mismatch (stored " +
                           hex32(stored_crc) + ", computed " + hex32(computed) +
                           "): the topic table is damaged");
    const unsigned char* p = head.data() + kFilePreamble;
    const unsigned char* end = p + body;
    auto need = [&](std::size_t n, const char* what) {
      if (static_cast<std::size_t>(end - p) < n)
        throw RecordingError(at(static_cast<std::uint64_t>(p - head.data())) +
                             "topic table ends inside " + what);
    };
    need(4, "the topic count");
    const auto count = get<std::uint32_t>(p);
    p += 4;
    if (count > kMaxTopics) throw RecordingError(at(16) + "implausible topic count");
    auto text = [&](const char* what) {
      need(4, what);
      const auto n = get<std::uint32_t>(p);
      p += 4;
      if (n > kMaxName)
        throw RecordingError(at(static_cast<std::uint64_t>(p - head.data())) + std::string(what) +
                             " longer than 4096 bytes");
      need(n, what);
      std::string s(reinterpret_cast<const char*>(p), n);
      p += n;
      return s;
    };
    for (std::uint32_t i = 0; i < count; ++i) {
      RecordingTopic t;
      t.name = text("a topic name");
      need(8, "a type id");
      t.type_id = get<std::uint64_t>(p);
      p += 8;
      t.type_name = text("a type name");
      topics.push_back(std::move(t));
    }
    if (p != end)
      throw RecordingError(at(static_cast<std::uint64_t>(p - head.data())) +
                           "unexpected bytes after the topic table");
    data_start = head.size();
    selected.assign(topics.size(), options.topics.empty());
    for (const auto& name : options.topics) {
      bool found = false;
      for (std::size_t i = 0; i < topics.size(); ++i) {
        if (topics[i].name == name) selected[i] = found = true;
      }
      if (!found) {
        std::string list;
        for (const auto& t : topics) list += (list.empty() ? "" : ", ") + t.name;
        throw RecordingError(path + ": no topic '" + name + "' in the recording (it has: " + list +
                             ")");
      }
    }
  }

  [[noreturn]] void notRecording(const unsigned char* p, std::uint64_t size) const {
    throw RecordingError(path + ": not a Tessera recording: expected the magic bytes " +
                         hexBytes(kFileMagic, 8) + " at byte 0, found " +
                         hexBytes(p, static_cast<std::size_t>(std::min<std::uint64_t>(size, 8))));
  }

  // Uses the footer and index when both are intact; returns false otherwise.
  bool readIndex() {
    const std::uint64_t size = source->size();
    if (size < data_start + kFooter) return false;
    unsigned char f[kFooter];
    if (!source->read(size - kFooter, kFooter, f) || get<std::uint32_t>(f) != kFooterMagic)
      return false;
    if (get<std::uint32_t>(f + 4) != crc(f + 8, 16)) {
      losses.push_back({size - kFooter, kFooter, 0, "footer checksum mismatch; blocks scanned"});
      return false;
    }
    const auto offset = get<std::uint64_t>(f + 8);
    const auto bytes = get<std::uint64_t>(f + 16);
    auto damaged = [&](const std::string& why) {
      losses.push_back({offset, bytes, 0, "index " + why + "; blocks scanned instead"});
      return false;
    };
    if (offset < data_start || offset > size - kFooter || bytes != size - kFooter - offset ||
        bytes < kIndexHead + 4 || bytes > kMaxBlockBytes)
      return damaged("position in the footer is impossible");
    std::vector<unsigned char> index(bytes);
    source->read(offset, bytes, index.data());
    if (get<std::uint32_t>(index.data() + bytes - 4) != crc(index.data(), bytes - 4))
      return damaged("checksum mismatch");
    const auto nblocks = get<std::uint32_t>(index.data() + 4);
    const auto ntopics = get<std::uint32_t>(index.data() + 8);
    if (get<std::uint32_t>(index.data()) != kIndexMagic || ntopics != topics.size() ||
        kIndexHead + std::uint64_t{nblocks} * kIndexEntry + std::uint64_t{ntopics} * 8 + 4 != bytes)
      return damaged("structure does not match the file");
    std::vector<Block> parsed;
    std::uint64_t prev_end = data_start;
    for (std::uint32_t i = 0; i < nblocks; ++i) {
      const unsigned char* e = index.data() + kIndexHead + std::size_t{i} * kIndexEntry;
      Block b{get<std::uint64_t>(e), get<std::uint32_t>(e + 8), get<Nanos>(e + 16),
              get<Nanos>(e + 24)};
      if (b.offset < prev_end || b.offset > offset || offset - b.offset < kBlockHeader)
        return damaged("entry " + std::to_string(i) + " points outside the block area");
      prev_end = b.offset + kBlockHeader;
      parsed.push_back(b);
    }
    const unsigned char* counts = index.data() + kIndexHead + std::size_t{nblocks} * kIndexEntry;
    topic_counts.resize(ntopics);
    for (std::uint32_t i = 0; i < ntopics; ++i)
      topic_counts[i] = get<std::uint64_t>(counts + 8 * i);
    blocks = std::move(parsed);
    data_end = offset;
    return true;
  }

  // Position of the next valid block header at or after `from`, or data_end.
  std::uint64_t resync(std::uint64_t from) const {
    std::vector<unsigned char> buf(std::size_t{1} << 16);
    std::string why;
    for (std::uint64_t pos = from; pos + kBlockHeader <= data_end;) {
      const std::size_t n =
          static_cast<std::size_t>(std::min<std::uint64_t>(buf.size(), data_end - pos));
      source->read(pos, n, buf.data());
      for (std::size_t i = 0; i + 4 <= n; ++i) {
        if (get<std::uint32_t>(buf.data() + i) != kBlockMagic) continue;
        unsigned char h[kBlockHeader];
        if (source->read(pos + i, kBlockHeader, h) && decodeBlockHeader(h, why)) return pos + i;
      }
      if (n < 4) break;
      pos += n - 3;  // a magic may straddle the chunk boundary
    }
    return data_end;
  }

  // Without an index: walks the block headers from the first block to the end of the file.
  void scanBlocks() {
    data_end = source->size();
    topic_counts.assign(topics.size(), 0);
    std::uint64_t pos = data_start;
    std::string why;
    while (pos < data_end) {
      unsigned char h[kBlockHeader] = {};
      const auto avail =
          static_cast<std::size_t>(std::min<std::uint64_t>(kBlockHeader, data_end - pos));
      source->read(pos, avail, h);
      // The start of an index (even its first bytes) ends the blocks of a closed file.
      const bool index_tail =
          avail >= 2 && std::memcmp(h, "TIDX", std::min<std::size_t>(avail, 4)) == 0;
      if (avail < kBlockHeader && !index_tail) {
        losses.push_back(
            {pos, data_end - pos, std::nullopt, "file ends inside a block header (truncated)"});
        break;
      }
      if (index_tail) {
        // The file was closed but its tail is damaged: the blocks before the index are whole.
        losses.push_back({pos, data_end - pos, 0, "index or footer damaged; blocks scanned"});
        break;
      }
      auto header = decodeBlockHeader(h, why);
      if (!header) {
        const std::uint64_t next = resync(pos + 1);
        losses.push_back({pos, next - pos, std::nullopt, why});
        pos = next;
        continue;
      }
      const std::uint64_t end = pos + kBlockHeader + header->stored;
      if (end > data_end) {
        losses.push_back({pos, data_end - pos, header->messages,
                          "block truncated: its header announces " +
                              std::to_string(header->stored) + " payload bytes, the file has " +
                              std::to_string(data_end - pos - kBlockHeader)});
        break;
      }
      blocks.push_back(Block{pos, header->messages, header->first, header->last});
      pos = end;
    }
  }

  // Loads block `i` into payload/raw; records a loss and returns false when it is damaged.
  bool loadBlock(std::size_t i) {
    const Block& b = blocks[i];
    const std::uint64_t limit = i + 1 < blocks.size() ? blocks[i + 1].offset : data_end;
    unsigned char h[kBlockHeader];
    std::string why;
    auto lose = [&](std::uint64_t bytes, const std::string& what) {
      losses.push_back({b.offset, bytes, b.messages, what});
      return false;
    };
    if (!source->read(b.offset, kBlockHeader, h))
      return lose(limit - b.offset, "file ends inside a block header");
    auto header = decodeBlockHeader(h, why);
    if (!header) return lose(limit - b.offset, why);
    const std::uint64_t bytes = kBlockHeader + header->stored;
    if (b.offset + bytes > limit)
      return lose(limit - b.offset, "block payload of " + std::to_string(header->stored) +
                                        " bytes overruns the next block or the index");
    stored.resize(header->stored);
    if (!source->read(b.offset + kBlockHeader, stored.size(), stored.data()))
      return lose(limit - b.offset, "file ends inside the block payload");
    const auto computed = crc(stored.data(), stored.size());
    if (computed != header->payload_crc)
      return lose(bytes, "block payload checksum mismatch (stored " + hex32(header->payload_crc) +
                             ", computed " + hex32(computed) + ")");
    if (header->flags & kFlagZstd) {
      const auto content = ZSTD_getFrameContentSize(stored.data(), stored.size());
      if (content != header->raw)
        return lose(bytes, "zstd frame size does not match the block header");
      raw.resize(header->raw);
      const std::size_t n = ZSTD_decompress(raw.data(), raw.size(), stored.data(), stored.size());
      if (ZSTD_isError(n) || n != raw.size())
        return lose(bytes, std::string("zstd decompression failed: ") +
                               (ZSTD_isError(n) ? ZSTD_getErrorName(n) : "short output"));
      payload = raw.data();
    } else {
      payload = stored.data();
    }
    payload_size = static_cast<std::size_t>(header->raw);
    cursor = 0;
    block_offset = b.offset;
    block_bytes = bytes;
    block_messages = header->messages;
    block_seen = 0;
    return true;
  }

  bool next(RecordedMessage& out) {
    for (;;) {
      if (payload == nullptr) {
        if (next_block >= blocks.size()) return false;
        if (!loadBlock(next_block++)) continue;
      }
      if (block_seen == block_messages) {
        if (cursor != payload_size)
          losses.push_back({block_offset, block_bytes, 0,
                            std::to_string(payload_size - cursor) +
                                " bytes after the last record of the block"});
        payload = nullptr;
        continue;
      }
      const std::uint64_t record = block_offset + cursor;
      auto truncateBlock = [&](const std::string& what) {
        losses.push_back({block_offset, block_bytes, block_messages - block_seen,
                          "record " + std::to_string(block_seen) + " (payload byte " +
                              std::to_string(cursor) + "): " + what});
        payload = nullptr;
      };
      if (payload_size - cursor < kRecordHeader) {
        truncateBlock("payload ends inside a record header");
        continue;
      }
      const auto topic = get<std::uint32_t>(payload + cursor);
      const auto length = get<std::uint32_t>(payload + cursor + 4);
      const auto stamp = get<Nanos>(payload + cursor + 8);
      if (topic >= topics.size()) {
        truncateBlock("topic index " + std::to_string(topic) + " is not in the topic table");
        continue;
      }
      if (length % 8 != 0 || length > payload_size - cursor - kRecordHeader) {
        truncateBlock("message length " + std::to_string(length) + " is not a multiple of 8 " +
                      "inside the block");
        continue;
      }
      const unsigned char* bytes = payload + cursor + kRecordHeader;
      cursor += kRecordHeader + length;
      ++block_seen;
      if (!indexed) ++topic_counts[topic];
      if (!selected[topic] || stamp < skip_before) continue;
      try {
        out.message = decodeMessage(
            std::span<const std::byte>(reinterpret_cast<const std::byte*>(bytes), length),
            at(record) + "message on '" + topics[topic].name + "'", options.limits);
      } catch (const MessageError& e) {
        losses.push_back({record, kRecordHeader + length, 1, e.what()});
        continue;
      }
      out.topic = topic;
      out.stamp = stamp;
      return true;
    }
  }
};

RecordingReader::RecordingReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {
  impl_->readFileHeader();
  impl_->indexed = impl_->readIndex();
  if (!impl_->indexed) impl_->scanBlocks();
}

RecordingReader::RecordingReader(const std::string& path, RecordingReaderOptions options)
    : RecordingReader([&] {
        auto impl = std::make_unique<Impl>();
        impl->path = path;
        impl->source = std::make_unique<FileSource>(path);
        impl->options = std::move(options);
        return impl;
      }()) {}

RecordingReader RecordingReader::fromBytes(std::string name, std::vector<unsigned char> bytes,
                                           RecordingReaderOptions options) {
  auto impl = std::make_unique<Impl>();
  impl->path = std::move(name);
  impl->source = std::make_unique<MemorySource>(std::move(bytes));
  impl->options = std::move(options);
  return RecordingReader(std::move(impl));
}

RecordingReader::~RecordingReader() = default;
RecordingReader::RecordingReader(RecordingReader&&) noexcept = default;
RecordingReader& RecordingReader::operator=(RecordingReader&&) noexcept = default;

const std::string& RecordingReader::path() const {
  return impl_->path;
}
std::uint32_t RecordingReader::version() const {
  return impl_->version;
}
const std::vector<RecordingTopic>& RecordingReader::topics() const {
  return impl_->topics;
}
bool RecordingReader::indexed() const {
  return impl_->indexed;
}
std::uint64_t RecordingReader::blockCount() const {
  return impl_->blocks.size();
}
std::uint64_t RecordingReader::messageCount() const {
  std::uint64_t n = 0;
  for (const auto& b : impl_->blocks) n += b.messages;
  return n;
}
const std::vector<std::uint64_t>& RecordingReader::topicCounts() const {
  return impl_->topic_counts;
}
Nanos RecordingReader::firstStamp() const {
  Nanos t = 0;
  bool any = false;
  for (const auto& b : impl_->blocks) {
    t = any ? std::min(t, b.first) : b.first;
    any = true;
  }
  return t;
}
Nanos RecordingReader::lastStamp() const {
  Nanos t = 0;
  bool any = false;
  for (const auto& b : impl_->blocks) {
    t = any ? std::max(t, b.last) : b.last;
    any = true;
  }
  return t;
}
bool RecordingReader::next(RecordedMessage& out) {
  return impl_->next(out);
}
void RecordingReader::seek(Nanos t) {
  auto& im = *impl_;
  im.payload = nullptr;
  im.skip_before = t;
  im.next_block = 0;
  while (im.next_block < im.blocks.size() && im.blocks[im.next_block].last < t) ++im.next_block;
}
const std::vector<RecordingLoss>& RecordingReader::losses() const {
  return impl_->losses;
}

}  // namespace tessera
