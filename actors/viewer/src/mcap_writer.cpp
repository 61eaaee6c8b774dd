// McapWriter: MCAP records in little-endian byte order, chunked, zstd-compressed, indexed.
#include <tessera/viewer/mcap_writer.hpp>

#include <unistd.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <utility>

namespace tessera::viewer {

namespace {

constexpr std::uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};

enum Opcode : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kStatistics = 0x0B,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

/// Appends little-endian fields to a byte vector.
struct Bytes {
  std::vector<std::uint8_t>& out;
  template <class T>
  void num(T v) {
    for (std::size_t i = 0; i < sizeof(T); ++i)
      out.push_back(static_cast<std::uint8_t>(static_cast<std::uint64_t>(v) >> (8 * i)));
  }
  void raw(const void* data, std::size_t size) {
    const auto* p = static_cast<const std::uint8_t*>(data);
    out.insert(out.end(), p, p + size);
  }
  void str(const std::string& s) {
    num(static_cast<std::uint32_t>(s.size()));
    raw(s.data(), s.size());
  }
};

/// A record: opcode, u64 length, content.
void record(std::vector<std::uint8_t>& out, std::uint8_t op,
            const std::vector<std::uint8_t>& content) {
  Bytes b{out};
  b.num(op);
  b.num(static_cast<std::uint64_t>(content.size()));
  b.raw(content.data(), content.size());
}

std::uint32_t crc(std::uint32_t running, const std::vector<std::uint8_t>& bytes) {
  return static_cast<std::uint32_t>(crc32(running, bytes.data(), static_cast<uInt>(bytes.size())));
}

}  // namespace

McapWriter::McapWriter(std::string path, McapWriterOptions options)
    : path_(std::move(path)), options_(std::move(options)) {
  // Written under a temporary name and renamed by close(): `path` is only ever a whole file.
  file_ = std::fopen(partialPath().c_str(), "wb");
  if (!file_)
    throw McapError("mcap: cannot create '" + partialPath() + "': " + std::strerror(errno));
  std::vector<std::uint8_t> head(kMagic, kMagic + 8), header;
  Bytes h{header};
  h.str(options_.profile);
  h.str(options_.library);
  record(head, kHeader, header);
  emit(head);
}

McapWriter::~McapWriter() {
  if (!file_) return;
  try {
    close();
  } catch (const McapError&) {  // a destructor cannot report it; close() does
  }
}

void McapWriter::emit(const std::vector<std::uint8_t>& bytes) {
  if (!file_) throw McapError("mcap: '" + path_ + "' is closed");
  if (std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size())
    throw McapError("mcap: cannot write '" + path_ + "': " + std::strerror(errno));
  offset_ += bytes.size();
  stats_.file_bytes = offset_;
}

std::uint16_t McapWriter::addSchema(const std::string& name, const std::string& encoding,
                                    const std::string& data) {
  if (schema_count_ == 0xFFFF) throw McapError("mcap: '" + path_ + "': too many schemas");
  const auto id = static_cast<std::uint16_t>(++schema_count_);
  std::vector<std::uint8_t> content, rec;
  Bytes b{content};
  b.num(id);
  b.str(name);
  b.str(encoding);
  b.num(static_cast<std::uint32_t>(data.size()));
  b.raw(data.data(), data.size());
  record(rec, kSchema, content);
  emit(rec);
  schemas_.insert(schemas_.end(), rec.begin(), rec.end());
  return id;
}

std::uint16_t McapWriter::addChannel(std::uint16_t schema_id, const std::string& topic,
                                     const std::string& message_encoding,
                                     const std::map<std::string, std::string>& metadata) {
  if (channel_count_ == 0xFFFF) throw McapError("mcap: '" + path_ + "': too many channels");
  if (schema_id > schema_count_)
    throw McapError("mcap: '" + path_ + "': channel '" + topic + "' names unknown schema " +
                    std::to_string(schema_id));
  const auto id = static_cast<std::uint16_t>(++channel_count_);  // ids from 1, as schemas
  std::vector<std::uint8_t> content, rec, map;
  Bytes m{map};
  for (const auto& [k, v] : metadata) {
    m.str(k);
    m.str(v);
  }
  Bytes b{content};
  b.num(id);
  b.num(schema_id);
  b.str(topic);
  b.str(message_encoding);
  b.num(static_cast<std::uint32_t>(map.size()));
  b.raw(map.data(), map.size());
  record(rec, kChannel, content);
  emit(rec);
  channels_.insert(channels_.end(), rec.begin(), rec.end());
  channel_counts_[id] = 0;
  return id;
}

void McapWriter::write(std::uint16_t channel, std::uint64_t log_time, const std::string& data) {
  write(channel, log_time, log_time,
        std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(data.data()),
                                      data.size()));
}

void McapWriter::write(std::uint16_t channel, std::uint64_t log_time, std::uint64_t publish_time,
                       std::span<const std::uint8_t> data) {
  if (!file_) throw McapError("mcap: '" + path_ + "' is closed");
  if (channel == 0 || channel > channel_count_)
    throw McapError("mcap: '" + path_ + "': message on unknown channel " + std::to_string(channel));
  if (chunk_.empty()) chunk_start_ = chunk_end_ = log_time;
  chunk_start_ = std::min(chunk_start_, log_time);
  chunk_end_ = std::max(chunk_end_, log_time);
  chunk_index_[channel].emplace_back(log_time, chunk_.size());
  Bytes b{chunk_};
  b.num(kMessage);
  b.num(static_cast<std::uint64_t>(2 + 4 + 8 + 8 + data.size()));
  b.num(channel);
  b.num(sequence_[channel]++);
  b.num(log_time);
  b.num(publish_time);
  b.raw(data.data(), data.size());
  if (stats_.messages == 0) first_time_ = last_time_ = log_time;
  first_time_ = std::min(first_time_, log_time);
  last_time_ = std::max(last_time_, log_time);
  ++stats_.messages;
  ++channel_counts_[channel];
  if (chunk_.size() >= options_.chunk_bytes) flushChunk();
}

void McapWriter::flushChunk() {
  if (chunk_.empty()) return;
  std::vector<std::uint8_t> packed;
  std::string compression;
  if (options_.compression == McapWriterOptions::Compression::kZstd) {
    compression = "zstd";
    packed.resize(ZSTD_compressBound(chunk_.size()));
    const std::size_t n =
        ZSTD_compress(packed.data(), packed.size(), chunk_.data(), chunk_.size(), 1);
    if (ZSTD_isError(n)) throw McapError("mcap: '" + path_ + "': zstd: " + ZSTD_getErrorName(n));
    packed.resize(n);
  } else {
    packed = chunk_;
  }
  const std::uint64_t chunk_offset = offset_;
  std::vector<std::uint8_t> content, rec;
  Bytes b{content};
  b.num(chunk_start_);
  b.num(chunk_end_);
  b.num(static_cast<std::uint64_t>(chunk_.size()));
  b.num(crc(0, chunk_));
  b.str(compression);
  b.num(static_cast<std::uint64_t>(packed.size()));
  b.raw(packed.data(), packed.size());
  record(rec, kChunk, content);
  emit(rec);
  const std::uint64_t chunk_length = offset_ - chunk_offset;

  // A message index per channel in the chunk, right after it.
  const std::uint64_t indexes_offset = offset_;
  std::vector<std::uint8_t> offsets;  // map<channel, offset> for the chunk index
  Bytes o{offsets};
  for (const auto& [channel, entries] : chunk_index_) {
    o.num(channel);
    o.num(offset_);
    std::vector<std::uint8_t> index, irec;
    Bytes i{index};
    i.num(channel);
    i.num(static_cast<std::uint32_t>(entries.size() * 16));
    for (const auto& [time, at] : entries) {
      i.num(time);
      i.num(at);
    }
    record(irec, kMessageIndex, index);
    emit(irec);
  }
  std::vector<std::uint8_t> ci;
  Bytes c{ci};
  c.num(chunk_start_);
  c.num(chunk_end_);
  c.num(chunk_offset);
  c.num(chunk_length);
  c.num(static_cast<std::uint32_t>(offsets.size()));
  c.raw(offsets.data(), offsets.size());
  c.num(offset_ - indexes_offset);
  c.str(compression);
  c.num(static_cast<std::uint64_t>(packed.size()));
  c.num(static_cast<std::uint64_t>(chunk_.size()));
  record(chunk_indexes_, kChunkIndex, ci);
  ++stats_.chunks;
  chunk_.clear();
  chunk_index_.clear();
}

void McapWriter::close() {
  if (!file_) return;
  flushChunk();
  // The data section's CRC is left 0, "not available" in the format: writers differ on where
  // the section starts, and chunks and the summary carry CRCs of their own.
  std::vector<std::uint8_t> end, end_content;
  Bytes{end_content}.num(std::uint32_t{0});
  record(end, kDataEnd, end_content);
  emit(end);

  // Summary: groups of schemas, channels, statistics, chunk indexes; then one summary offset
  // per group. Its CRC runs from the summary's start through the footer's second field.
  const std::uint64_t summary_start = offset_;
  std::vector<std::uint8_t> summary, offsets;
  auto group = [&](std::uint8_t op, const std::vector<std::uint8_t>& records) {
    if (records.empty()) return;
    std::vector<std::uint8_t> content;
    Bytes c{content};
    c.num(op);
    c.num(summary_start + summary.size());
    c.num(static_cast<std::uint64_t>(records.size()));
    record(offsets, kSummaryOffset, content);
    summary.insert(summary.end(), records.begin(), records.end());
  };
  std::vector<std::uint8_t> statistics, st;
  Bytes s{st};
  s.num(stats_.messages);
  s.num(schema_count_);
  s.num(static_cast<std::uint32_t>(channel_count_));
  s.num(std::uint32_t{0});  // attachments
  s.num(std::uint32_t{0});  // metadata
  s.num(static_cast<std::uint32_t>(stats_.chunks));
  s.num(first_time_);
  s.num(last_time_);
  std::vector<std::uint8_t> counts;
  Bytes cc{counts};
  for (const auto& [channel, n] : channel_counts_) {
    cc.num(channel);
    cc.num(n);
  }
  s.num(static_cast<std::uint32_t>(counts.size()));
  s.raw(counts.data(), counts.size());
  record(statistics, kStatistics, st);
  group(kSchema, schemas_);
  group(kChannel, channels_);
  group(kStatistics, statistics);
  group(kChunkIndex, chunk_indexes_);
  const std::uint64_t summary_offset_start = summary_start + summary.size();
  std::vector<std::uint8_t> tail = summary;
  tail.insert(tail.end(), offsets.begin(), offsets.end());
  std::vector<std::uint8_t> footer;
  Bytes f{footer};
  f.num(kFooter);
  f.num(std::uint64_t{8 + 8 + 4});
  f.num(summary_start);
  f.num(summary_offset_start);
  tail.insert(tail.end(), footer.begin(), footer.end());
  const std::uint32_t summary_crc = crc(0, tail);
  Bytes t{tail};
  t.num(summary_crc);
  t.raw(kMagic, 8);
  const bool written = std::fwrite(tail.data(), 1, tail.size(), file_) == tail.size() &&
                       std::fflush(file_) == 0 && ::fsync(::fileno(file_)) == 0;
  const int write_errno = errno;
  const bool closed = std::fclose(file_) == 0;
  file_ = nullptr;
  if (!written || !closed)
    throw McapError("mcap: cannot write '" + partialPath() +
                    "': " + std::strerror(written ? errno : write_errno) + " ('" + path_ +
                    "' was not replaced)");
  if (std::rename(partialPath().c_str(), path_.c_str()) != 0)
    throw McapError("mcap: cannot rename '" + partialPath() + "' to '" + path_ +
                    "': " + std::strerror(errno));
  offset_ += tail.size();
  stats_.file_bytes = offset_;
}

}  // namespace tessera::viewer
