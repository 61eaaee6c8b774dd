// EmulatorHost: see emulator_host.hpp.
#include <tessera/drivers/emulator_host.hpp>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <random>
#include <vector>

namespace tessera::drivers {

std::int64_t hostNowNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

namespace {

int listenOn(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) throw LinkError(std::string("socket: ") + std::strerror(errno));
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || ::listen(fd, 1) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    throw LinkError("cannot listen on 127.0.0.1:" + std::to_string(port) + ": " + why);
  }
  return fd;
}

int boundPort(int fd) {
  sockaddr_in a{};
  socklen_t len = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  return ntohs(a.sin_port);
}

void closeFd(int& fd) {
  if (fd >= 0) ::close(fd);
  fd = -1;
}

}  // namespace

EmulatorHost::EmulatorHost(EmulatedDevice device, EmulatorHostOptions options)
    : device_(std::move(device)), options_(std::move(options)) {
  if (!device_.receive || !device_.poll || !device_.next_due)
    throw std::invalid_argument("EmulatorHost: the device needs receive, poll and next_due");
  wake_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wake_fd_ < 0) throw LinkError(std::string("eventfd: ") + std::strerror(errno));
  if (options_.tcp_port >= 0) {
    listen_fd_ = listenOn(options_.tcp_port);
    port_ = boundPort(listen_fd_);
  } else {
    baudConstant(options_.baud);  // a rate the pty can be set to
    pty_ = std::make_unique<PseudoTerminal>(options_.link);
  }
  plugs_ = 1;
  thread_ = std::thread([this] { run(); });
}

EmulatorHost::~EmulatorHost() {
  stop_ = true;
  const std::uint64_t one = 1;
  [[maybe_unused]] const auto n = ::write(wake_fd_, &one, sizeof one);
  if (thread_.joinable()) thread_.join();
  closeFd(client_fd_);
  closeFd(listen_fd_);
  closeFd(wake_fd_);
}

std::string EmulatorHost::devicePath() const {
  if (options_.tcp_port >= 0) return "tcp://127.0.0.1:" + std::to_string(port_);
  return options_.link.empty() ? pty_->slavePath() : options_.link;
}

void EmulatorHost::unplug(double down_s) {
  unplug_request_ = std::max<std::int64_t>(1, static_cast<std::int64_t>(down_s * 1e9));
  const std::uint64_t one = 1;
  [[maybe_unused]] const auto n = ::write(wake_fd_, &one, sizeof one);
}

void EmulatorHost::run() {
  std::mt19937 rng(7);
  bool plugged = true;
  while (!stop_) {
    const std::int64_t now = hostNowNs();
    if (const std::int64_t down = unplug_request_.exchange(0); down > 0) {
      if (pty_) pty_->close();
      closeFd(client_fd_);
      closeFd(listen_fd_);
      plugged = false;
      unplug_until_ = now + down;
    }
    if (!plugged && now >= unplug_until_) {
      try {
        if (pty_)
          pty_->reopen();
        else
          listen_fd_ = listenOn(port_);
        plugged = true;
        ++plugs_;
        std::lock_guard lock(mutex_);
        if (device_.restart) device_.restart(now);
      } catch (const LinkError&) {
        unplug_until_ = now + 100'000'000;  // the port is still taken: try again shortly
      }
    }
    // What to wait for: the port, the wake-up event, and the device's next output.
    std::vector<pollfd> fds{{wake_fd_, POLLIN, 0}};
    int io = -1;
    if (plugged) {
      if (pty_) {
        io = pty_->master();
      } else if (client_fd_ >= 0) {
        io = client_fd_;
      } else {
        fds.push_back({listen_fd_, POLLIN, 0});
      }
      if (io >= 0) fds.push_back({io, POLLIN, 0});
    }
    std::int64_t wait_ns = 100'000'000;
    {
      std::lock_guard lock(mutex_);
      if (const auto due = device_.next_due(); due && plugged && io >= 0)
        wait_ns = std::clamp<std::int64_t>(*due - now, 0, wait_ns);
    }
    if (!plugged) wait_ns = std::clamp<std::int64_t>(unplug_until_ - now, 0, wait_ns);
    const timespec timeout{static_cast<time_t>(wait_ns / 1'000'000'000),
                           static_cast<long>(wait_ns % 1'000'000'000)};
    ::ppoll(fds.data(), fds.size(), &timeout, nullptr);
    if (fds[0].revents & POLLIN) {
      std::uint64_t v;
      [[maybe_unused]] const auto n = ::read(wake_fd_, &v, sizeof v);
    }
    if (stop_ || !plugged) continue;
    if (!pty_ && client_fd_ < 0) {
      if (fds.size() > 1 && (fds[1].revents & POLLIN))
        client_fd_ = ::accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC);
      continue;
    }
    const std::int64_t t = hostNowNs();
    char buf[4096];
    const ssize_t n = ::read(io, buf, sizeof buf);
    if (n == 0 && !pty_) {  // the driver closed its connection: wait for the next one
      closeFd(client_fd_);
      continue;
    }
    std::lock_guard lock(mutex_);
    // At different rates each side sees the other's bytes as noise.
    const bool mismatch =
        pty_ && pty_->slaveBaud() != (device_.baud ? device_.baud() : options_.baud);
    if (n > 0) {
      bytes_in_ += n;
      if (mismatch) {
        std::string noise(static_cast<std::size_t>(n) * 2, '\0');
        for (auto& c : noise) c = static_cast<char>(rng() | 0x80u);
        [[maybe_unused]] const auto w = ::write(io, noise.data(), noise.size());
        continue;
      }
      device_.receive(std::string_view(buf, static_cast<std::size_t>(n)), t);
    }
    std::string out = device_.poll(t);
    if (mismatch)
      for (auto& c : out) c = static_cast<char>(rng() | 0x80u);
    // Like a UART with nobody listening, what the port does not take is lost.
    for (std::size_t at = 0; at < out.size();) {
      const ssize_t w = ::write(io, out.data() + at, out.size() - at);
      if (w <= 0) break;
      at += static_cast<std::size_t>(w);
      bytes_out_ += w;
    }
  }
}

}  // namespace tessera::drivers
