// Line-oriented reading of dataset text files, plain or gzip-compressed (recognised from the
// content, not the name), with error messages that name the file and line.
//
// Every dataset parser in hw/datasets builds on this: TextReader yields lines, Fields splits a
// line into whitespace- (or comma-) separated tokens and converts them with checks, and
// ParseReport counts what a lenient parser skipped so that nothing is dropped silently.
// Numbers are parsed with std::from_chars: "nan", "inf" and out-of-range values are rejected
// unless the caller asks for them (Fields::real with allow_non_finite).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::io {

// A dataset file cannot be read or a line is malformed. what() is "FILE:LINE: message" (or
// "FILE: message" when no line applies).
class DatasetError : public std::runtime_error {
 public:
  DatasetError(const std::filesystem::path& file, std::size_t line, const std::string& message);
  const std::filesystem::path& file() const { return file_; }
  std::size_t line() const { return line_; }  // 1-based; 0 = not tied to a line

 private:
  std::filesystem::path file_;
  std::size_t line_;
};

// Reads a file line by line; gzip data (magic 1f 8b) is decompressed on the fly with zlib.
// A truncated or corrupt gzip stream throws DatasetError instead of ending quietly.
class TextReader {
 public:
  explicit TextReader(std::filesystem::path path);  // throws DatasetError if it cannot be opened
  // Reads `contents` (plain text only) as if it were the file `name`: for tests and fuzzing.
  static TextReader fromString(std::filesystem::path name, std::string contents);
  ~TextReader();
  TextReader(TextReader&&) noexcept;
  TextReader& operator=(TextReader&&) noexcept;

  // The next line without its end-of-line ("\n" or "\r\n"); false at the end of the file.
  // Lines longer than max_line_bytes throw (a binary file read as text, not a dataset).
  bool next(std::string& line);

  std::size_t lineNumber() const { return line_; }  // of the line last returned
  const std::filesystem::path& path() const { return path_; }
  bool compressed() const;
  // Fraction of the file (compressed bytes) consumed so far, for progress displays.
  double progress() const;

  // Throws DatasetError("FILE:LINE: message") for the line last returned.
  [[noreturn]] void fail(const std::string& message) const;

  static constexpr std::size_t max_line_bytes = 64 << 20;

 private:
  struct Source;
  std::filesystem::path path_;
  TextReader() = default;
  std::unique_ptr<Source> source_;
  std::size_t line_ = 0;
};

// Reads a whole (possibly gzip) file into lines; convenience for small files.
std::vector<std::string> readLines(const std::filesystem::path& path);

// Tokens of one line and checked conversions. Errors name the field (by the caller's label)
// and its value, e.g. "intel.clf:12: field 3 (range count): expected an integer, got 'x1'".
class Fields {
 public:
  // Splits on spaces/tabs, or on `separator` too when it is not '\0' (e.g. ',').
  Fields(const TextReader& reader, std::string_view line, char separator = '\0');
  Fields(std::filesystem::path file, std::size_t line_number, std::string_view line,
         char separator = '\0');

  std::size_t size() const { return tokens_.size(); }
  bool empty() const { return tokens_.empty(); }
  std::string_view operator[](std::size_t i) const { return tokens_.at(i); }

  // Throws unless there are at least / exactly n fields.
  void requireAtLeast(std::size_t n, std::string_view what) const;
  void requireExactly(std::size_t n, std::string_view what) const;

  double real(std::size_t i, std::string_view label, bool allow_non_finite = false) const;
  std::int64_t integer(std::size_t i, std::string_view label) const;
  // Integer in [lo, hi]; "huge" counts and indices are rejected before anything is allocated.
  std::int64_t integerIn(std::size_t i, std::string_view label, std::int64_t lo,
                         std::int64_t hi) const;

  [[noreturn]] void fail(const std::string& message) const;

 private:
  std::filesystem::path file_;
  std::size_t line_;
  std::vector<std::string_view> tokens_;
};

// What a lenient parser read and skipped. Skips are counted per reason; the first few are kept
// with their line numbers so a user can look at them.
struct ParseReport {
  std::size_t lines = 0;    // lines read, comments and blanks included
  std::size_t records = 0;  // records produced
  std::size_t skipped = 0;  // lines skipped (sum of skipped_by_reason)
  std::map<std::string, std::size_t> skipped_by_reason;
  std::vector<std::string> first_skips;  // "FILE:LINE: reason", at most max_examples

  static constexpr std::size_t max_examples = 10;
  void skip(const TextReader& reader, const std::string& reason);
  void skip(const std::filesystem::path& file, std::size_t line, const std::string& reason);
  std::string describe() const;  // one line, e.g. "5000 records, 12 lines skipped (PARAM: 12)"
};

}  // namespace tessera::io
