#include <tessera/io/text_reader.hpp>

#include <zlib.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

namespace tessera::io {
namespace {

std::string location(const std::filesystem::path& file, std::size_t line) {
  std::string s = file.string();
  if (line > 0) {
    s.push_back(':');
    s.append(std::to_string(line));
  }
  return s;
}

std::string quoted(std::string_view token) {
  constexpr std::size_t kMax = 40;
  std::string s(token.substr(0, kMax));
  if (token.size() > kMax) s += "...";
  return "'" + s + "'";
}

}  // namespace

DatasetError::DatasetError(const std::filesystem::path& file, std::size_t line,
                           const std::string& message)
    : std::runtime_error(location(file, line) + ": " + message), file_(file), line_(line) {}

// One of: a plain file through stdio, or a gzip stream through zlib's gzFile (which also reads
// plain files, but we want to know which one it is and to report a truncated stream).
struct TextReader::Source {
  gzFile gz = nullptr;
  bool is_gzip = false;
  std::uintmax_t file_size = 0;
  std::vector<char> buffer = std::vector<char>(1 << 16);
  std::size_t begin = 0, end = 0;
  bool eof = false;
  bool in_memory = false;

  ~Source() {
    if (gz) gzclose(gz);
  }
};

TextReader::TextReader(std::filesystem::path path) : path_(std::move(path)) {
  std::error_code ec;
  if (std::filesystem::is_directory(path_, ec)) throw DatasetError(path_, 0, "is a directory");
  std::ifstream probe(path_, std::ios::binary);
  if (!probe) throw DatasetError(path_, 0, "cannot open file");
  unsigned char magic[2] = {0, 0};
  probe.read(reinterpret_cast<char*>(magic), 2);
  source_ = std::make_unique<Source>();
  source_->is_gzip = probe.gcount() == 2 && magic[0] == 0x1f && magic[1] == 0x8b;
  source_->file_size = std::filesystem::file_size(path_, ec);
  if (ec) source_->file_size = 0;
  source_->gz = gzopen(path_.c_str(), "rb");
  if (!source_->gz) throw DatasetError(path_, 0, "cannot open file");
  gzbuffer(source_->gz, 1 << 17);
}

TextReader TextReader::fromString(std::filesystem::path name, std::string contents) {
  TextReader reader;
  reader.path_ = std::move(name);
  reader.source_ = std::make_unique<Source>();
  reader.source_->in_memory = true;
  reader.source_->file_size = contents.size();
  reader.source_->buffer.assign(contents.begin(), contents.end());
  reader.source_->end = reader.source_->buffer.size();
  reader.source_->eof = true;
  return reader;
}

TextReader::~TextReader() = default;
TextReader::TextReader(TextReader&&) noexcept = default;
TextReader& TextReader::operator=(TextReader&&) noexcept = default;

bool TextReader::compressed() const {
  return source_->is_gzip;
}

double TextReader::progress() const {
  if (source_->file_size == 0) return 0;
  const double consumed = source_->in_memory ? static_cast<double>(source_->begin)
                                             : static_cast<double>(gzoffset(source_->gz));
  return std::min(1.0, consumed / static_cast<double>(source_->file_size));
}

bool TextReader::next(std::string& line) {
  Source& s = *source_;
  line.clear();
  bool any = false;
  while (true) {
    if (s.begin == s.end) {
      if (s.eof) break;
      const int n = gzread(s.gz, s.buffer.data(), static_cast<unsigned>(s.buffer.size()));
      if (n < 0) {
        int code = 0;
        const char* msg = gzerror(s.gz, &code);
        throw DatasetError(path_, line_ + 1,
                           std::string("cannot decompress: ") + (msg ? msg : "zlib error"));
      }
      if (n == 0) {
        // gzread reports a truncated stream as a short read plus an error state.
        int code = 0;
        const char* msg = gzerror(s.gz, &code);
        if (code != Z_OK && code != Z_STREAM_END)
          throw DatasetError(path_, line_ + 1,
                             std::string("truncated or corrupt gzip data: ") + (msg ? msg : ""));
        s.eof = true;
        break;
      }
      s.begin = 0;
      s.end = static_cast<std::size_t>(n);
    }
    const char* start = s.buffer.data() + s.begin;
    const std::size_t avail = s.end - s.begin;
    const void* nl = std::memchr(start, '\n', avail);
    const std::size_t take = nl ? static_cast<const char*>(nl) - start : avail;
    if (line.size() + take > max_line_bytes)
      throw DatasetError(
          path_, line_ + 1,
          "line longer than " + std::to_string(max_line_bytes) + " bytes; is this a text dataset?");
    line.append(start, take);
    any = true;
    s.begin += take;
    if (nl) {
      ++s.begin;
      break;
    }
  }
  if (!any) return false;
  if (!line.empty() && line.back() == '\r') line.pop_back();
  ++line_;
  return true;
}

void TextReader::fail(const std::string& message) const {
  throw DatasetError(path_, line_, message);
}

std::vector<std::string> readLines(const std::filesystem::path& path) {
  TextReader reader(path);
  std::vector<std::string> lines;
  std::string line;
  while (reader.next(line)) lines.push_back(line);
  return lines;
}

Fields::Fields(const TextReader& reader, std::string_view line, char separator)
    : Fields(reader.path(), reader.lineNumber(), line, separator) {}

Fields::Fields(std::filesystem::path file, std::size_t line_number, std::string_view line,
               char separator)
    : file_(std::move(file)), line_(line_number) {
  std::size_t i = 0;
  const auto is_sep = [separator](char c) {
    return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f' ||
           (separator != '\0' && c == separator);
  };
  while (i < line.size()) {
    while (i < line.size() && is_sep(line[i])) ++i;
    const std::size_t start = i;
    while (i < line.size() && !is_sep(line[i])) ++i;
    if (i > start) tokens_.push_back(line.substr(start, i - start));
  }
}

void Fields::fail(const std::string& message) const {
  throw DatasetError(file_, line_, message);
}

void Fields::requireAtLeast(std::size_t n, std::string_view what) const {
  if (tokens_.size() < n)
    fail(std::string(what) + ": expected at least " + std::to_string(n) + " fields, got " +
         std::to_string(tokens_.size()));
}

void Fields::requireExactly(std::size_t n, std::string_view what) const {
  if (tokens_.size() != n)
    fail(std::string(what) + ": expected " + std::to_string(n) + " fields, got " +
         std::to_string(tokens_.size()));
}

double Fields::real(std::size_t i, std::string_view label, bool allow_non_finite) const {
  const std::string where = "field " + std::to_string(i + 1) + " (" + std::string(label) + ")";
  if (i >= tokens_.size())
    fail(where + ": missing (line has " + std::to_string(size()) + " fields)");
  std::string_view t = tokens_[i];
  if (!t.empty() && t.front() == '+') t.remove_prefix(1);
  double value = 0;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec == std::errc::result_out_of_range)
    fail(where + ": number out of range, got " + quoted(tokens_[i]));
  if (ec != std::errc() || ptr != t.data() + t.size())
    fail(where + ": expected a number, got " + quoted(tokens_[i]));
  if (!allow_non_finite && !std::isfinite(value))
    fail(where + ": expected a finite number, got " + quoted(tokens_[i]));
  return value;
}

std::int64_t Fields::integer(std::size_t i, std::string_view label) const {
  const std::string where = "field " + std::to_string(i + 1) + " (" + std::string(label) + ")";
  if (i >= tokens_.size())
    fail(where + ": missing (line has " + std::to_string(size()) + " fields)");
  std::string_view t = tokens_[i];
  if (!t.empty() && t.front() == '+') t.remove_prefix(1);
  std::int64_t value = 0;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec == std::errc::result_out_of_range)
    fail(where + ": integer out of range, got " + quoted(tokens_[i]));
  if (ec != std::errc() || ptr != t.data() + t.size())
    fail(where + ": expected an integer, got " + quoted(tokens_[i]));
  return value;
}

std::int64_t Fields::integerIn(std::size_t i, std::string_view label, std::int64_t lo,
                               std::int64_t hi) const {
  const std::int64_t v = integer(i, label);
  if (v < lo || v > hi)
    fail("field " + std::to_string(i + 1) + " (" + std::string(label) + "): expected " +
         std::to_string(lo) + ".." + std::to_string(hi) + ", got " + std::to_string(v));
  return v;
}

void ParseReport::skip(const TextReader& reader, const std::string& reason) {
  skip(reader.path(), reader.lineNumber(), reason);
}

void ParseReport::skip(const std::filesystem::path& file, std::size_t line,
                       const std::string& reason) {
  ++skipped;
  ++skipped_by_reason[reason];
  if (first_skips.size() < max_examples)
    first_skips.push_back(location(file, line) + ": " + reason);
}

std::string ParseReport::describe() const {
  std::ostringstream out;
  out << records << " records from " << lines << " lines";
  if (skipped > 0) {
    out << ", " << skipped << " lines skipped (";
    bool first = true;
    for (const auto& [reason, count] : skipped_by_reason) {
      out << (first ? "" : ", ") << reason << ": " << count;
      first = false;
    }
    out << ")";
  }
  return out.str();
}

}  // namespace tessera::io
