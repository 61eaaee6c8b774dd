// `bench ipc` over a Unix-domain stream socket: length-framed messages (the Wire header's size),
// the full payload copied into the kernel and out again each way, as a socket transport would.
#include "transports.hpp"

#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera::app::ipc {

namespace {

void writeAll(int fd, const std::byte* p, std::size_t n) {
  while (n > 0) {
    const ssize_t w = ::send(fd, p, n, MSG_NOSIGNAL);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) throw std::runtime_error(std::string("uds: send failed: ") + std::strerror(errno));
    p += w;
    n -= static_cast<std::size_t>(w);
  }
}

/// Buffered reading of length-framed messages from a stream socket (as a socket transport
/// would): one recv() may bring several small messages; a large one is copied out in pieces.
class UdsReader {
 public:
  explicit UdsReader(int fd) : fd_(fd), buffer_(kSizes.back() + (std::size_t{1} << 16)) {}
  /// Returns the next whole message's header and the time its last byte arrived.
  std::pair<Wire, Nanos> next() {
    fill(sizeof(Wire));
    const Wire w = readWire(buffer_.data() + begin_);
    if (w.bytes < sizeof(Wire) || w.bytes > kSizes.back()) {
      throw std::runtime_error("uds: bad frame of " + std::to_string(w.bytes) + " bytes");
    }
    fill(w.bytes);
    const Nanos taken = steadyNow();
    begin_ += w.bytes;
    return {w, taken};
  }

 private:
  void fill(std::size_t n) {
    if (end_ - begin_ >= n) return;
    if (begin_ + n > buffer_.size()) {  // compact
      std::memmove(buffer_.data(), buffer_.data() + begin_, end_ - begin_);
      end_ -= begin_;
      begin_ = 0;
    }
    while (end_ - begin_ < n) {
      const ssize_t r = ::recv(fd_, buffer_.data() + end_, buffer_.size() - end_, 0);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) throw std::runtime_error("uds: the other end closed the socket");
      end_ += static_cast<std::size_t>(r);
    }
  }
  int fd_;
  std::vector<std::byte> buffer_;
  std::size_t begin_ = 0, end_ = 0;
};

/// A message buffer written in advance and sent whole.
class UdsSender {
 public:
  UdsSender(int fd, Fill fill) : fd_(fd), buffer_(kSizes.back()), fill_(fill) {}
  void* prepare(std::size_t bytes, Kind kind, std::int64_t value = 0) {
    if (bytes_ != bytes) {
      fill_(buffer_.data(), bytes, kind, value);
      bytes_ = bytes;
    }
    return buffer_.data();
  }
  /// Sends a control message now, leaving the prepared buffer alone.
  void control(Wire w) {
    std::array<std::byte, kControlBytes> small{};
    w.bytes = kControlBytes;
    w.stamp = steadyNow();
    writeWire(small.data(), w);
    writeAll(fd_, small.data(), small.size());
  }
  void* current() { return buffer_.data(); }
  void send() {
    writeAll(fd_, buffer_.data(), bytes_);
    bytes_ = 0;  // built again next time, as --fill says
  }

 private:
  int fd_;
  std::vector<std::byte> buffer_;
  PayloadFiller fill_;
  std::size_t bytes_ = 0;
};

class UdsLeader final : public LeaderLink {
 public:
  UdsLeader(int fd, Fill fill) : sender_(fd, fill), reader_(fd) {}
  void build(std::size_t bytes, Kind kind, std::int64_t value) override {
    sender_.prepare(bytes, kind, value);
  }
  Nanos send() override {
    const Nanos stamp = stampWire(sender_.current());
    sender_.send();
    return stamp;
  }
  std::pair<Wire, Nanos> receive() override { return reader_.next(); }

 private:
  UdsSender sender_;
  UdsReader reader_;
};

}  // namespace

SocketPair::SocketPair() {
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, fds) != 0) {
    throw std::runtime_error(std::string("bench ipc: socketpair: ") + std::strerror(errno));
  }
}

SocketPair::~SocketPair() {
  ::close(fds[0]);
  ::close(fds[1]);
}

int udsFollower(int fd, Fill fill) {
  UdsSender sender(fd, fill);
  UdsReader reader(fd);
  FollowerLogic logic;
  for (;;) {
    const auto [in, taken] = reader.next();
    const bool more = logic.handle(
        in, taken, 0, [&](std::size_t bytes) { return sender.prepare(bytes, Kind::kPong); },
        [&] { sender.send(); }, [&](const Wire& w) { sender.control(w); });
    if (!more) return 0;
  }
}

void udsLeader(int fd, const Options& o, TransportResult& out) {
  UdsLeader link(fd, o.fill);
  lead(link, o, out);
}

}  // namespace tessera::app::ipc
