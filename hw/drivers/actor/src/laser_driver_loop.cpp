#include <tessera/drivers/laser_driver_loop.hpp>

#include <tessera/drivers/byte_link.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>

#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <iostream>
#include <sstream>

namespace tessera::drivers {

namespace laser_loop_detail {

std::string seconds(double s) {
  std::ostringstream out;
  out << s;
  return out.str();
}

double threadCpuSeconds() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + static_cast<double>(ts.tv_nsec) * 1e-9;
}

/// Prints driver events to stderr, at most one a second, with how many were held back: a
/// device spewing bad replies must not flood the log.
class EventLog {
 public:
  EventLog(std::string name, std::string device)
      : prefix_("[" + std::move(name) + "] " + std::move(device) + ": ") {}
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

}  // namespace laser_loop_detail

void checkLaserLinkOptions(const std::string& actor, const LaserLinkOptions& o) {
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

LaserDriverLoop::LaserDriverLoop(std::string name, LaserLinkOptions link, LaserSession& session,
                                 ActorContext& ctx, Publisher<msg::LaserScan> scan,
                                 std::string frame_id, std::vector<double> mount)
    : name_(std::move(name)),
      link_(std::move(link)),
      session_(session),
      ctx_(ctx),
      scan_pub_(scan),
      frame_id_(std::move(frame_id)),
      mount_(std::move(mount)) {
  wake_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wake_fd_ < 0) throw std::runtime_error(name_ + ": eventfd failed");
}

LaserDriverLoop::~LaserDriverLoop() {
  stop();
  ::close(wake_fd_);
}

void LaserDriverLoop::start() {
  thread_ = std::thread([this] { run(); });
}

void LaserDriverLoop::stop() {
  stop_ = true;
  const std::uint64_t one = 1;
  [[maybe_unused]] const auto n = ::write(wake_fd_, &one, sizeof one);
  if (thread_.joinable()) thread_.join();
}

bool LaserDriverLoop::waitOrStop(double seconds) {
  pollfd p{wake_fd_, POLLIN, 0};
  ::poll(&p, 1, static_cast<int>(std::ceil(seconds * 1000)));
  return stop_;
}

void LaserDriverLoop::run() {
  namespace d = laser_loop_detail;
  d::EventLog log(name_, link_.device);
  double delay = link_.retry_initial_s;
  bool in_outage = false;
  const auto keepStats = [this] {
    std::lock_guard lock(stats_mutex_);
    stats_.session = session_.counters();
    stats_.model = session_.model();
  };
  while (!stop_) {
    const int baud = session_.openBaud(link_.baud);
    ByteLink link;
    try {
      link = ByteLink::open(link_.device, baud);
    } catch (const LinkError& e) {
      {
        std::lock_guard lock(stats_mutex_);
        ++stats_.open_failures;
        stats_.last_error = e.what();
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
      stats_.baud = baud;
    }
    std::string reason;
    const std::int64_t scans_at_open = session_.counters().scans;
    // Does what the session asks; false when the link must be dropped.
    const auto handle = [&](SessionOutput&& out, Nanos read_at) {
      for (const auto& e : out.events) log(e);
      for (const auto& scan : out.scans) {
        publish(scan);
        const double ms = nanosToSeconds(steadyNow() - read_at) * 1e3;
        std::lock_guard lock(stats_mutex_);
        // The latest samples only, so a driver that runs for days stays the same size.
        constexpr std::size_t kKept = 4096;
        if (stats_.latency_ms.size() < kKept)
          stats_.latency_ms.push_back(ms);
        else
          stats_.latency_ms[static_cast<std::size_t>(stats_.published) % kKept] = ms;
        stats_.latency_max_ms = std::max(stats_.latency_max_ms, ms);
      }
      if (out.switch_baud > 0) {
        link.setBaud(out.switch_baud);
        std::lock_guard lock(stats_mutex_);
        stats_.baud = out.switch_baud;
      }
      if (!out.send.empty()) link.writeAll(out.send);
      if (out.reconnect) reason = out.reconnect_reason;
      return !out.reconnect;
    };
    try {
      handle(session_.connected(ctx_.now()), steadyNow());
      std::string bytes;
      while (!stop_) {
        pollfd fds[2] = {{link.fd(), POLLIN, 0}, {wake_fd_, POLLIN, 0}};
        ::poll(fds, 2, 50);
        bytes.clear();
        if (fds[0].revents) link.readSome(bytes);
        const Nanos read_at = steadyNow();
        const Nanos now = ctx_.now();
        if (!bytes.empty() && !handle(session_.received(bytes, now), read_at)) break;
        if (!handle(session_.tick(now), read_at)) break;
        if (in_outage && session_.streaming()) {
          log.always("connected, streaming");
          in_outage = false;
        }
      }
    } catch (const LinkError& e) {
      reason = e.what();
    }
    const bool worked = session_.counters().scans > scans_at_open;
    session_.disconnected();
    link.close();
    keepStats();
    if (stop_) break;
    {
      std::lock_guard lock(stats_mutex_);
      stats_.last_error = reason;
      ++stats_.reconnects;
    }
    if (worked) delay = link_.retry_initial_s;
    log.always(reason + "; reconnecting in " + d::seconds(delay) + " s");
    in_outage = true;
    if (waitOrStop(delay)) break;
    delay = std::min(2 * delay, link_.retry_max_s);
  }
  keepStats();
  std::lock_guard lock(stats_mutex_);
  stats_.cpu_s = d::threadCpuSeconds();
}

void LaserDriverLoop::publish(const LaserReading& r) {
  auto loan =
      scan_pub_.loan(r.ranges.size() * sizeof(float) * (r.intensities.empty() ? 1 : 2) + 256);
  auto b = loan.builder();
  setHeader(b.initHeader(), r.stamp_ns, frame_id_, scan_pub_.nextSeq());
  b.setAngleMin(r.angle_min);
  b.setAngleIncrement(r.angle_increment);
  b.setRangeMin(r.range_min);
  b.setRangeMax(r.range_max);
  b.setScanTimeS(r.scan_time);
  b.setMountX(static_cast<float>(mount_[0]));
  b.setMountY(static_cast<float>(mount_[1]));
  b.setMountTheta(static_cast<float>(mount_[2]));
  auto ranges = mutableView<float>(b.initRanges(static_cast<unsigned>(r.ranges.size())));
  std::copy(r.ranges.begin(), r.ranges.end(), ranges.begin());
  if (!r.intensities.empty()) {
    auto in = mutableView<float>(b.initIntensities(static_cast<unsigned>(r.intensities.size())));
    std::copy(r.intensities.begin(), r.intensities.end(), in.begin());
  }
  scan_pub_.publish(std::move(loan));
  std::lock_guard lock(stats_mutex_);
  ++stats_.published;
  stats_.clock_offset_ms = nanosToSeconds(r.stamp_ns - r.received_ns) * 1e3;
}

void LaserDriverLoop::summarize(Summary& out) const {
  std::lock_guard lock(stats_mutex_);
  const auto& s = stats_;
  out["scans_published"] = s.published;
  out["sessions"] = s.session.sessions;
  out["reconnects"] = s.reconnects;
  out["open_failures"] = s.open_failures;
  out["bad_replies"] = s.session.bad_replies;
  out["refusals"] = s.session.refusals;
  out["garbage_bytes"] = static_cast<std::int64_t>(s.session.garbage_bytes);
  std::vector<double> l = s.latency_ms;
  double median = 0, p99 = 0;
  if (!l.empty()) {
    std::sort(l.begin(), l.end());
    median = l[l.size() / 2];
    p99 = l[std::min(l.size() - 1, l.size() * 99 / 100)];
  }
  out["latency_ms_median"] = median;
  out["latency_ms_p99"] = p99;
  out["latency_ms_max"] = s.latency_max_ms;
  out["stamp_minus_receive_ms"] = s.clock_offset_ms;
  out["cpu_s"] = s.cpu_s;
  out["model"] = s.model;
  out["baud"] = s.baud;
  out["last_error"] = s.last_error;
}

}  // namespace tessera::drivers

namespace tessera::drivers {

LaserDriverActor::LaserDriverActor(std::string name, LaserLinkOptions link, std::string frame_id,
                                   std::vector<double> mount)
    : name_(std::move(name)),
      link_(std::move(link)),
      frame_id_(std::move(frame_id)),
      mount_(std::move(mount)) {
  checkLaserLinkOptions(name_, link_);
  if (mount_.size() != 3 ||
      !std::all_of(mount_.begin(), mount_.end(), [](double v) { return std::isfinite(v); }))
    fail("mount", "needs 3 finite values [x, y, theta]");
}

LaserDriverActor::~LaserDriverActor() = default;

void LaserDriverActor::fail(const std::string& key, const std::string& what) const {
  throw ConfigError(name_ + ": option '" + key + "': " + what);
}

void LaserDriverActor::configure(ActorContext& ctx) {
  requireWallClock(name_, ctx);
  loop_ = std::make_unique<LaserDriverLoop>(
      name_, link_, *session_, ctx, ctx.advertise<msg::LaserScan>("scan"), frame_id_, mount_);
}

void LaserDriverActor::start() {
  loop_->start();
}

void LaserDriverActor::stop() {
  if (loop_) loop_->stop();
}

void LaserDriverActor::summarize(Summary& out) const {
  if (loop_) loop_->summarize(out);
}

}  // namespace tessera::drivers
