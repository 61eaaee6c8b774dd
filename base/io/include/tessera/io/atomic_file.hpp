// Output files that are never half-written: maps, trajectories, graphs, summaries and the other
// files a run leaves behind are written to a temporary file in the target's folder and renamed
// over the target only once complete (flushed, checked and fsync'ed). A reader, or a run that
// was killed mid-write, sees either the previous complete file or the new complete one.
//
// AtomicFile owns its temporary file: commit() moves it to the target, and destroying it without
// commit() (an exception while writing, an abandoned write) removes it and leaves any existing
// target untouched. Rename is atomic only within one file system, so the temporary file lives
// next to the target: "<target>.tmp.<pid>.<n>". A process killed mid-write (SIGKILL) leaves its
// temporary file; the next writer of the same target removes the ones whose process is gone.
//
// Every failure throws FileWriteError whose message starts with the target file and gives the
// reason from the system, e.g. "out/map.pgm: cannot write: No space left on device" or
// "out/x/map.yaml: cannot create: the folder out/x does not exist".
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <ostream>
#include <stdexcept>
#include <string>
#include <string_view>

namespace tessera::io {

/// what() is "FILE: reason"; file() and reason() give the two parts (for callers that report
/// through their own error type).
class FileWriteError : public std::runtime_error {
 public:
  FileWriteError(const std::filesystem::path& file, const std::string& reason)
      : std::runtime_error(file.string() + ": " + reason), file_(file), reason_(reason) {}
  const std::filesystem::path& file() const { return file_; }
  const std::string& reason() const { return reason_; }

 private:
  std::filesystem::path file_;
  std::string reason_;
};

class AtomicFile {
 public:
  /// Creates the temporary file next to `target`; throws FileWriteError when it cannot.
  explicit AtomicFile(std::filesystem::path target);
  AtomicFile(AtomicFile&&) noexcept;
  AtomicFile& operator=(AtomicFile&&) noexcept;
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  /// Without commit(): removes the temporary file; the target is left as it was.
  ~AtomicFile();

  /// The content goes here (buffered). A failed write shows in commit() with its reason.
  std::ostream& stream();
  void write(std::string_view bytes);
  /// Hands what is buffered to the temporary file (for files streamed over a long run: a crash
  /// then leaves the data under the temporary name). Throws FileWriteError on a failed write.
  void flush();

  /// Flushes, fsyncs and closes the temporary file, then renames it over the target. Throws
  /// FileWriteError (the temporary file removed, the target untouched) when any step fails.
  void commit();

  const std::filesystem::path& target() const;
  const std::filesystem::path& tempPath() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The whole file in one go: AtomicFile, write, commit.
void writeFileAtomically(const std::filesystem::path& target, std::string_view content);

/// For writers that only take a file name (PCL, OctoMap): `write` writes the temporary file
/// "<folder>/<stem>.tmp.<pid>.<n><extension>" (the extension kept, as such libraries pick the
/// format from it); it is then fsync'ed and renamed over `target`. If `write` throws, or leaves
/// no file, the temporary file is removed and the target is untouched (the exception passes on;
/// a missing file throws FileWriteError).
void replaceFileAtomically(const std::filesystem::path& target,
                           const std::function<void(const std::filesystem::path& temp)>& write);

}  // namespace tessera::io
