#include <tessera/drivers/device_loop.hpp>

#include <tessera/drivers/byte_link.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>

#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <sstream>

namespace tessera::drivers {

namespace device_loop_detail {

std::string seconds(double s) {
  std::ostringstream out;
  out << s;
  return out.str();
}

/// Prints driver events to stderr, at most one a second, with how many were held back: a
/// device spewing bad replies must not flood the log.
class EventLog {
 public:
  EventLog(const std::string& name, const std::string& device)
      : prefix_("[" + name + "] " + device + ": ") {}
  void operator()(const std::string& event) {
    const Nanos now = steadyNow();
    if (now - last_ < kNanosPerSecond) {
      ++held_;
      return;
    }
    std::cerr << prefix_ << event;
    if (held_ > 0) std::cerr << " (and " << held_ << " more events)";
    std::cerr << "\n";
    held_ = 0;
    last_ = now;
  }
  void always(const std::string& event) {
    last_ = 0;
    (*this)(event);
  }

 private:
  std::string prefix_;
  Nanos last_ = 0;
  std::int64_t held_ = 0;
};

}  // namespace device_loop_detail

void checkLinkOptions(const std::string& actor, const DeviceLinkOptions& o) {
  const auto fail = [&actor](const std::string& key, const std::string& what) {
    throw ConfigError(actor + ": option '" + key + "': " + what);
  };
  if (o.device.empty())
    fail("device", "is required (e.g. /dev/ttyACM0, /dev/ttyUSB0 or tcp://192.168.0.10:10940)");
  if (o.baud != 0) {
    try {
      baudConstant(o.baud);
    } catch (const LinkError& e) {
      fail("baud", e.what());
    }
  }
  if (!(o.retry_initial_s > 0) || !std::isfinite(o.retry_initial_s))
    fail("retry_initial_s", "must be finite and > 0");
  if (!(o.retry_max_s >= o.retry_initial_s) || !std::isfinite(o.retry_max_s))
    fail("retry_max_s", "must be finite and >= retry_initial_s");
}

void requireWallClock(const std::string& actor, const ActorContext& ctx) {
  if (ctx.clock().kind() != ClockKind::kWall)
    throw ConfigError(actor +
                      ": a device driver needs the wall clock: set 'clock: wall' in the profile "
                      "(or --set clock=wall)");
}

DeviceLoop::DeviceLoop(std::string name, DeviceLinkOptions link, DeviceHooks hooks,
                       ActorContext& ctx)
    : name_(std::move(name)), link_(std::move(link)), hooks_(std::move(hooks)), ctx_(ctx) {
  wake_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wake_fd_ < 0) throw std::runtime_error(name_ + ": eventfd failed");
}

DeviceLoop::~DeviceLoop() {
  stop();
  ::close(wake_fd_);
}

void DeviceLoop::start() {
  thread_ = std::thread([this] { run(); });
}

void DeviceLoop::wake() {
  const std::uint64_t one = 1;
  [[maybe_unused]] const auto n = ::write(wake_fd_, &one, sizeof one);
}

void DeviceLoop::stop() {
  stop_ = true;
  wake();
  if (thread_.joinable()) thread_.join();
}

bool DeviceLoop::waitOrStop(double seconds) {
  // The whole back-off, whatever wake() calls (commands) come meanwhile; only stop() ends it.
  const Nanos end = steadyNow() + secondsToNanos(seconds);
  while (!stop_) {
    const Nanos left = end - steadyNow();
    if (left <= 0) break;
    pollfd p{wake_fd_, POLLIN, 0};
    ::poll(&p, 1, static_cast<int>(std::ceil(nanosToSeconds(left) * 1000)));
    std::uint64_t v;
    [[maybe_unused]] const auto n = ::read(wake_fd_, &v, sizeof v);
  }
  return stop_;
}

void DeviceLoop::run() {
  namespace d = device_loop_detail;
  d::EventLog log(name_, link_.device);
  double delay = link_.retry_initial_s;
  bool in_outage = false;
  while (!stop_) {
    const int baud = hooks_.open_baud ? hooks_.open_baud(link_.baud) : link_.baud;
    ByteLink link;
    try {
      link = ByteLink::open(link_.device, baud);
    } catch (const LinkError& e) {
      {
        std::lock_guard lock(stats_mutex_);
        ++open_failures_;
        last_error_ = e.what();
      }
      if (!in_outage)
        log.always(std::string("cannot open: ") + e.what() + "; retrying every " +
                   d::seconds(delay) + " s and up to " + d::seconds(link_.retry_max_s) + " s");
      in_outage = true;
      if (waitOrStop(delay)) break;
      delay = std::min(2 * delay, link_.retry_max_s);
      continue;
    }
    {
      std::lock_guard lock(stats_mutex_);
      baud_ = baud;
    }
    std::string reason;
    const std::int64_t progress_at_open = hooks_.progress();
    // Does what the session asks; false when the link must be dropped.
    const auto apply = [&](DeviceStep&& step) {
      for (const auto& e : step.events) log(e);
      if (step.switch_baud > 0) {
        link.setBaud(step.switch_baud);
        std::lock_guard lock(stats_mutex_);
        baud_ = step.switch_baud;
      }
      if (!step.send.empty()) link.writeAll(step.send);
      if (step.reconnect) reason = step.reconnect_reason;
      return !step.reconnect;
    };
    try {
      apply(hooks_.connected(ctx_.now()));
      std::string bytes;
      while (!stop_) {
        pollfd fds[2] = {{link.fd(), POLLIN, 0}, {wake_fd_, POLLIN, 0}};
        ::poll(fds, 2, 50);
        if (fds[1].revents) {
          std::uint64_t v;
          [[maybe_unused]] const auto n = ::read(wake_fd_, &v, sizeof v);
        }
        bytes.clear();
        if (fds[0].revents) link.readSome(bytes);
        const Nanos read_at = steadyNow();
        const Nanos now = ctx_.now();
        if (!bytes.empty() && !apply(hooks_.received(bytes, now, read_at))) break;
        if (!apply(hooks_.tick(now))) break;
        if (in_outage && hooks_.streaming()) {
          log.always("connected, streaming");
          in_outage = false;
        }
      }
    } catch (const LinkError& e) {
      reason = e.what();
    }
    const bool worked = hooks_.progress() > progress_at_open;
    hooks_.disconnected();
    link.close();
    if (stop_) break;
    {
      std::lock_guard lock(stats_mutex_);
      last_error_ = reason;
      ++reconnects_;
    }
    if (worked) delay = link_.retry_initial_s;
    log.always(reason + "; reconnecting in " + d::seconds(delay) + " s");
    in_outage = true;
    if (waitOrStop(delay)) break;
    delay = std::min(2 * delay, link_.retry_max_s);
  }
  std::lock_guard lock(stats_mutex_);
  cpu_s_ = threadCpuSeconds();
}

void DeviceLoop::summarize(Summary& out) const {
  std::lock_guard lock(stats_mutex_);
  out["reconnects"] = reconnects_;
  out["open_failures"] = open_failures_;
  out["baud"] = baud_;
  out["cpu_s"] = cpu_s_;
  out["last_error"] = last_error_;
}

}  // namespace tessera::drivers
