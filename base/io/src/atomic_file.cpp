// Temporary file + fsync + rename behind tessera/io/atomic_file.hpp. The file is written through
// a POSIX descriptor (an std::ofstream has none to fsync) with a small streambuf in front.
#include <tessera/io/atomic_file.hpp>

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tessera::io {
namespace fs = std::filesystem;

namespace atomic_file_detail {

[[noreturn]] void failWrite(const fs::path& target, const std::string& what) {
  throw FileWriteError(target, what);
}

std::string errnoText(int err) {
  return std::strerror(err);
}

fs::path folderOf(const fs::path& target) {
  return target.parent_path().empty() ? fs::path(".") : target.parent_path();
}

/// Why a file in `target`'s folder could not be created: a missing folder says so by name.
std::string createProblem(const fs::path& target, int err) {
  const fs::path folder = folderOf(target);
  std::error_code ec;
  if (err == ENOENT && !fs::exists(folder, ec))
    return "cannot create: the folder " + folder.string() + " does not exist";
  if (err == ENOTDIR || (fs::exists(folder, ec) && !fs::is_directory(folder, ec)))
    return "cannot create: " + folder.string() + " is not a folder";
  return "cannot create: " + errnoText(err);
}

/// "<target>.tmp.<pid>.<n>", or with `keep_extension` "<stem>.tmp.<pid>.<n><extension>".
fs::path tempName(const fs::path& target, bool keep_extension) {
  static std::atomic<unsigned> counter{0};
  const std::string tag =
      ".tmp." + std::to_string(::getpid()) + "." + std::to_string(counter.fetch_add(1));
  if (!keep_extension) return fs::path(target.string() + tag);
  fs::path name = target.stem();
  name += tag;
  name += target.extension();
  return target.parent_path() / name;
}

/// The pid in a temporary name's "<pid>.<n><suffix>" part, or 0 when `rest` is not one.
pid_t temporaryOwner(std::string_view rest, std::string_view suffix) {
  const auto digits = [](std::string_view t) {
    return !t.empty() &&
           std::all_of(t.begin(), t.end(), [](char c) { return c >= '0' && c <= '9'; });
  };
  if (rest.size() < suffix.size() || rest.substr(rest.size() - suffix.size()) != suffix) return 0;
  rest.remove_suffix(suffix.size());
  const auto dot = rest.find('.');
  if (dot == std::string_view::npos || !digits(rest.substr(0, dot)) ||
      !digits(rest.substr(dot + 1)) || dot > 9)
    return 0;
  return static_cast<pid_t>(std::stol(std::string(rest.substr(0, dot))));
}

/// Best effort: removes the temporary files of `target` (either naming) that a writer which no
/// longer runs left behind, killed before it could commit or discard them. A process that still
/// runs may be writing its own: those stay.
void removeStaleTemporaries(const fs::path& target) {
  const std::string name = target.filename().string();
  const std::string by_name = name + ".tmp.";
  const std::string by_stem = target.stem().string() + ".tmp.";
  const std::string ext = target.extension().string();
  std::error_code ec;
  for (fs::directory_iterator it(folderOf(target), ec), end; !ec && it != end; it.increment(ec)) {
    const std::string other = it->path().filename().string();
    pid_t pid = 0;
    if (other.rfind(by_name, 0) == 0)
      pid = temporaryOwner(std::string_view(other).substr(by_name.size()), "");
    if (pid == 0 && other.rfind(by_stem, 0) == 0)
      pid = temporaryOwner(std::string_view(other).substr(by_stem.size()), ext);
    if (pid <= 0 || pid == ::getpid()) continue;
    if (::kill(pid, 0) != 0 && errno == ESRCH) ::unlink(it->path().c_str());
  }
}

/// Best effort: makes the rename itself durable. A failure here loses nothing already renamed.
void syncFolder(const fs::path& target) {
  const int fd = ::open(folderOf(target).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

void renameOver(const fs::path& temp, const fs::path& target) {
  if (::rename(temp.c_str(), target.c_str()) != 0) {
    const int err = errno;
    ::unlink(temp.c_str());
    failWrite(target, "cannot replace: " + errnoText(err));
  }
  syncFolder(target);
}

/// Output buffer over a descriptor; the first write error is kept (errno) for commit().
class FdBuffer : public std::streambuf {
 public:
  explicit FdBuffer(int fd) : fd_(fd), buffer_(1 << 16) {
    setp(buffer_.data(), buffer_.data() + buffer_.size());
  }
  int error() const { return error_; }

  bool flushBuffer() {
    const char* p = pbase();
    std::size_t left = static_cast<std::size_t>(pptr() - pbase());
    setp(buffer_.data(), buffer_.data() + buffer_.size());
    while (left > 0 && error_ == 0) {
      const ssize_t n = ::write(fd_, p, left);
      if (n < 0) {
        if (errno == EINTR) continue;
        error_ = errno;
      } else if (n == 0) {
        error_ = EIO;
      } else {
        p += n;
        left -= static_cast<std::size_t>(n);
      }
    }
    return error_ == 0;
  }

 protected:
  int_type overflow(int_type c) override {
    if (!flushBuffer()) return traits_type::eof();
    if (!traits_type::eq_int_type(c, traits_type::eof())) {
      *pptr() = traits_type::to_char_type(c);
      pbump(1);
    }
    return traits_type::not_eof(c);
  }
  int sync() override { return flushBuffer() ? 0 : -1; }

 private:
  int fd_;
  std::vector<char> buffer_;
  int error_ = 0;
};

}  // namespace atomic_file_detail

using atomic_file_detail::failWrite;

struct AtomicFile::Impl {
  fs::path target, temp;
  int fd = -1;
  atomic_file_detail::FdBuffer buffer;
  std::ostream out;

  Impl(fs::path target_in, fs::path temp_in, int fd_in)
      : target(std::move(target_in)),
        temp(std::move(temp_in)),
        fd(fd_in),
        buffer(fd),
        out(&buffer) {}

  void discard() {
    if (fd >= 0) {
      ::close(fd);
      fd = -1;
      ::unlink(temp.c_str());
    }
  }
};

AtomicFile::AtomicFile(fs::path target) {
  atomic_file_detail::removeStaleTemporaries(target);
  fs::path temp = atomic_file_detail::tempName(target, false);
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (fd < 0) failWrite(target, atomic_file_detail::createProblem(target, errno));
  impl_ = std::make_unique<Impl>(std::move(target), std::move(temp), fd);
}

AtomicFile::AtomicFile(AtomicFile&&) noexcept = default;
AtomicFile& AtomicFile::operator=(AtomicFile&& other) noexcept {
  if (this != &other) {
    if (impl_) impl_->discard();
    impl_ = std::move(other.impl_);
  }
  return *this;
}

AtomicFile::~AtomicFile() {
  if (impl_) impl_->discard();
}

std::ostream& AtomicFile::stream() {
  return impl_->out;
}

void AtomicFile::write(std::string_view bytes) {
  impl_->out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

void AtomicFile::flush() {
  Impl& f = *impl_;
  if (f.fd < 0) failWrite(f.target, "already committed or discarded");
  if (!f.buffer.flushBuffer())
    failWrite(f.target, "cannot write: " + atomic_file_detail::errnoText(f.buffer.error()));
  if (!f.out) failWrite(f.target, "cannot write: the stream failed");
}

void AtomicFile::commit() {
  Impl& f = *impl_;
  if (f.fd < 0) failWrite(f.target, "already committed or discarded");
  int err = 0;
  if (!f.buffer.flushBuffer() || f.buffer.error() != 0) err = f.buffer.error();
  if (err == 0 && !f.out) err = EIO;  // a formatting failure with no system error behind it
  if (err == 0 && ::fsync(f.fd) != 0) err = errno;
  const int fd = std::exchange(f.fd, -1);
  if (::close(fd) != 0 && err == 0) err = errno;
  if (err != 0) {
    ::unlink(f.temp.c_str());
    failWrite(f.target, "cannot write: " + atomic_file_detail::errnoText(err));
  }
  atomic_file_detail::renameOver(f.temp, f.target);
}

const fs::path& AtomicFile::target() const {
  return impl_->target;
}
const fs::path& AtomicFile::tempPath() const {
  return impl_->temp;
}

void writeFileAtomically(const fs::path& target, std::string_view content) {
  AtomicFile file(target);
  file.write(content);
  file.commit();
}

void replaceFileAtomically(const fs::path& target,
                           const std::function<void(const fs::path&)>& write) {
  atomic_file_detail::removeStaleTemporaries(target);
  const fs::path temp = atomic_file_detail::tempName(target, true);
  std::error_code ec;
  if (!fs::is_directory(atomic_file_detail::folderOf(target), ec))
    failWrite(target, atomic_file_detail::createProblem(target, ENOENT));
  try {
    write(temp);
  } catch (...) {
    ::unlink(temp.c_str());
    throw;
  }
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) {
    const int err = errno;
    failWrite(target,
              "cannot write: the writer left no file (" + atomic_file_detail::errnoText(err) + ")");
  }
  int err = ::fsync(fd) != 0 ? errno : 0;
  if (::close(fd) != 0 && err == 0) err = errno;
  if (err != 0) {
    ::unlink(temp.c_str());
    failWrite(target, "cannot write: " + atomic_file_detail::errnoText(err));
  }
  atomic_file_detail::renameOver(temp, target);
}

}  // namespace tessera::io
