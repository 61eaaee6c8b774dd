// ByteLink and PseudoTerminal: see byte_link.hpp.
#include <tessera/drivers/byte_link.hpp>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <utility>

namespace tessera::drivers {

namespace {

std::string errnoText() {
  return std::strerror(errno);
}

constexpr std::array<std::pair<int, unsigned>, 12> kBauds{{{1200, B1200},
                                                           {2400, B2400},
                                                           {4800, B4800},
                                                           {9600, B9600},
                                                           {19200, B19200},
                                                           {38400, B38400},
                                                           {57600, B57600},
                                                           {115200, B115200},
                                                           {230400, B230400},
                                                           {460800, B460800},
                                                           {500000, B500000},
                                                           {921600, B921600}}};

/// "tcp://HOST:PORT" or "HOST:PORT" (numeric port): host and port; false for a device path.
bool tcpAddress(const std::string& device, std::string& host, std::string& port) {
  std::string s = device;
  const bool scheme = s.rfind("tcp://", 0) == 0;
  if (scheme) s = s.substr(6);
  if (!scheme && (s.empty() || s[0] == '/' || s[0] == '.')) return false;
  const auto colon = s.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == s.size()) {
    if (scheme) throw LinkError("'" + device + "': expected tcp://HOST:PORT");
    return false;
  }
  port = s.substr(colon + 1);
  for (const char c : port)
    if (c < '0' || c > '9') {
      if (scheme) throw LinkError("'" + device + "': port '" + port + "' is not a number");
      return false;
    }
  host = s.substr(0, colon);
  return true;
}

int openTcp(const std::string& device, const std::string& host, const std::string& port,
            int timeout_ms) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (const int e = ::getaddrinfo(host.c_str(), port.c_str(), &hints, &found); e != 0)
    throw LinkError("'" + device + "': " + ::gai_strerror(e));
  std::string error = "no address";
  for (addrinfo* a = found; a; a = a->ai_next) {
    const int fd = ::socket(a->ai_family, a->ai_socktype | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0) continue;
    if (::connect(fd, a->ai_addr, a->ai_addrlen) == 0 || errno == EINPROGRESS) {
      pollfd p{fd, POLLOUT, 0};
      int so_error = 0;
      socklen_t len = sizeof so_error;
      if (::poll(&p, 1, timeout_ms) == 1 &&
          ::getsockopt(fd, SOL_SOCKET, SO_ERROR, &so_error, &len) == 0 && so_error == 0) {
        const int one = 1;  // scans are small and latency matters
        ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        ::freeaddrinfo(found);
        return fd;
      }
      error = so_error ? std::strerror(so_error) : "connect timed out";
    } else {
      error = errnoText();
    }
    ::close(fd);
  }
  ::freeaddrinfo(found);
  throw LinkError("'" + device + "': " + error);
}

void makeRaw(int fd, int baud, const std::string& device) {
  termios t{};
  if (::tcgetattr(fd, &t) != 0) throw LinkError("'" + device + "': not a terminal: " + errnoText());
  ::cfmakeraw(&t);
  t.c_cflag |= CLOCAL | CREAD;
  t.c_cflag &= ~static_cast<tcflag_t>(CSTOPB | CRTSCTS);
  t.c_cc[VMIN] = 0;
  t.c_cc[VTIME] = 0;
  if (baud > 0) {
    const speed_t speed = baudConstant(baud);
    ::cfsetispeed(&t, speed);
    ::cfsetospeed(&t, speed);
  }
  if (::tcsetattr(fd, TCSANOW, &t) != 0)
    throw LinkError("'" + device + "': cannot set " + std::to_string(baud) +
                    " baud raw mode: " + errnoText());
}

}  // namespace

unsigned baudConstant(int baud) {
  for (const auto& [rate, constant] : kBauds)
    if (rate == baud) return constant;
  throw LinkError("baud rate " + std::to_string(baud) +
                  " is not a standard rate (1200 .. 921600, e.g. 19200, 57600, 115200, 500000)");
}

ByteLink ByteLink::open(const std::string& device, int baud, int timeout_ms) {
  if (device.empty()) throw LinkError("no device given");
  std::string host, port;
  if (tcpAddress(device, host, port)) return {openTcp(device, host, port, timeout_ms), device};
  const int fd = ::open(device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    const std::string why = errnoText();
    throw LinkError(
        "'" + device + "': " + why +
        (errno == EACCES ? " (add the user to the dialout group, or a udev rule)" : ""));
  }
  ByteLink link(fd, device, true);
  makeRaw(fd, baud, device);
  ::tcflush(fd, TCIOFLUSH);  // bytes from before this session are no answer to it
  return link;
}

ByteLink::ByteLink(ByteLink&& other) noexcept
    : fd_(std::exchange(other.fd_, -1)),
      device_(std::move(other.device_)),
      serial_(other.serial_) {}

void ByteLink::setBaud(int baud) {
  if (!serial_ || fd_ < 0) return;
  ::tcdrain(fd_);  // the command that asked for the new rate goes out at the old one
  makeRaw(fd_, baud, device_);
}

ByteLink& ByteLink::operator=(ByteLink&& other) noexcept {
  if (this != &other) {
    close();
    fd_ = std::exchange(other.fd_, -1);
    device_ = std::move(other.device_);
    serial_ = other.serial_;
  }
  return *this;
}

ByteLink::~ByteLink() {
  close();
}

void ByteLink::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

std::size_t ByteLink::readSome(std::string& out, std::size_t max_bytes) {
  if (fd_ < 0) throw LinkError("'" + device_ + "': not open");
  const std::size_t at = out.size();
  out.resize(at + max_bytes);
  const ssize_t n = ::read(fd_, out.data() + at, max_bytes);
  if (n > 0) {
    out.resize(at + static_cast<std::size_t>(n));
    return static_cast<std::size_t>(n);
  }
  out.resize(at);
  if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
    // Nothing to read, unless the other end hung up (a pty whose master closed, a socket).
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, 0) == 1 && (p.revents & (POLLHUP | POLLERR)) && !(p.revents & POLLIN))
      throw LinkError("'" + device_ + "': hung up");
    return 0;
  }
  throw LinkError("'" + device_ + "': " + (n == 0 ? std::string("disconnected") : errnoText()));
}

void ByteLink::writeAll(std::string_view bytes, int timeout_ms) {
  if (fd_ < 0) throw LinkError("'" + device_ + "': not open");
  while (!bytes.empty()) {
    const ssize_t n = ::write(fd_, bytes.data(), bytes.size());
    if (n > 0) {
      bytes.remove_prefix(static_cast<std::size_t>(n));
      continue;
    }
    if (n < 0 && errno != EAGAIN && errno != EINTR)
      throw LinkError("'" + device_ + "': write failed: " + errnoText());
    pollfd p{fd_, POLLOUT, 0};
    if (::poll(&p, 1, timeout_ms) != 1 || (p.revents & (POLLHUP | POLLERR)))
      throw LinkError("'" + device_ + "': the device takes no more bytes (write timed out)");
  }
}

PseudoTerminal::PseudoTerminal(std::string link) : link_(std::move(link)) {
  openPair();
}

PseudoTerminal::~PseudoTerminal() {
  close();
  if (!link_.empty()) {
    std::error_code ec;
    std::filesystem::remove(link_, ec);
  }
}

void PseudoTerminal::openPair() {
  master_ = ::posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (master_ < 0) throw LinkError("posix_openpt: " + errnoText());
  char name[128];
  if (::grantpt(master_) != 0 || ::unlockpt(master_) != 0 ||
      ::ptsname_r(master_, name, sizeof name) != 0) {
    const std::string why = errnoText();
    close();
    throw LinkError("pseudo-terminal: " + why);
  }
  slave_path_ = name;
  slave_ = ::open(name, O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (slave_ < 0) {
    const std::string why = errnoText();
    close();
    throw LinkError("'" + std::string(name) + "': " + why);
  }
  makeRaw(slave_, 115200, slave_path_);  // no echo, no line editing until a driver opens it
  if (!link_.empty()) {
    std::error_code ec;
    const std::filesystem::path tmp = link_ + ".new";
    std::filesystem::remove(tmp, ec);
    std::filesystem::create_symlink(slave_path_, tmp, ec);
    if (!ec) std::filesystem::rename(tmp, link_, ec);  // atomic: a driver never sees no link
    if (ec) throw LinkError("cannot link '" + link_ + "' to " + slave_path_ + ": " + ec.message());
  }
}

int PseudoTerminal::slaveBaud() const {
  termios t{};
  if (slave_ < 0 || ::tcgetattr(slave_, &t) != 0) return 0;
  const speed_t speed = ::cfgetispeed(&t);
  for (const auto& [rate, constant] : kBauds)
    if (constant == speed) return rate;
  return 0;
}

void PseudoTerminal::close() {
  if (slave_ >= 0) ::close(slave_);
  if (master_ >= 0) ::close(master_);
  slave_ = master_ = -1;
}

void PseudoTerminal::reopen() {
  close();
  openPair();
}

}  // namespace tessera::drivers
