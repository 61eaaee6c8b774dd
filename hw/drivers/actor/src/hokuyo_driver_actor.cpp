#include <tessera/drivers/hokuyo_driver_actor.hpp>

#include <tessera/drivers/byte_link.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/registry.hpp>

#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <iostream>
#include <sstream>

namespace tessera::drivers {

namespace hokuyo_detail {

[[noreturn]] void fail(const std::string& key, const std::string& what) {
  throw ConfigError("hokuyo_scip: option '" + key + "': " + what);
}

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

/// Prints driver events to stderr, at most one a second of the same kind, with how many were
/// held back: a device spewing bad replies must not flood the log.
class EventLog {
 public:
  explicit EventLog(std::string device) : device_(std::move(device)) {}
  void operator()(const std::string& event) {
    const Nanos now = steadyNow();
    if (now - last_ < kNanosPerSecond) {
      ++held_;
      return;
    }
    std::cerr << "[hokuyo_scip] " << device_ << ": " << event;
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
  std::string device_;
  Nanos last_ = 0;
  std::int64_t held_ = 0;
};

}  // namespace hokuyo_detail

HokuyoDriverActor::HokuyoDriverActor(HokuyoDriverOptions options) : options_(std::move(options)) {
  using hokuyo_detail::fail;
  const auto& o = options_;
  if (o.device.empty())
    fail("device", "is required (e.g. /dev/ttyACM0 or tcp://192.168.0.10:10940)");
  try {
    baudConstant(o.baud);
  } catch (const LinkError& e) {
    fail("baud", e.what());
  }
  if (o.mount.size() != 3 ||
      !std::all_of(o.mount.begin(), o.mount.end(), [](double v) { return std::isfinite(v); }))
    fail("mount", "needs 3 finite values [x, y, theta]");
  if (!(o.retry_initial_s > 0) || !std::isfinite(o.retry_initial_s))
    fail("retry_initial_s", "must be finite and > 0");
  if (!(o.retry_max_s >= o.retry_initial_s) || !std::isfinite(o.retry_max_s))
    fail("retry_max_s", "must be finite and >= retry_initial_s");
  try {
    ScipClient check(o.client);
  } catch (const std::invalid_argument& e) {
    fail("client", e.what());
  }
}

HokuyoDriverActor::~HokuyoDriverActor() {
  stop();
  if (wake_fd_ >= 0) ::close(wake_fd_);
}

void HokuyoDriverActor::configure(ActorContext& ctx) {
  if (ctx.clock().kind() != ClockKind::kWall)
    throw ConfigError(
        "hokuyo_scip: a device driver needs the wall clock: set 'clock: wall' in "
        "the profile (or --set clock=wall)");
  ctx_ = &ctx;
  scan_pub_ = ctx.advertise<msg::LaserScan>("scan");
  wake_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wake_fd_ < 0) throw std::runtime_error("hokuyo_scip: eventfd failed");
}

void HokuyoDriverActor::start() {
  thread_ = std::thread([this] { run(); });
}

void HokuyoDriverActor::stop() {
  stop_ = true;
  if (wake_fd_ >= 0) {
    const std::uint64_t one = 1;
    [[maybe_unused]] const auto n = ::write(wake_fd_, &one, sizeof one);
  }
  if (thread_.joinable()) thread_.join();
}

bool HokuyoDriverActor::waitOrStop(double seconds) {
  pollfd p{wake_fd_, POLLIN, 0};
  ::poll(&p, 1, static_cast<int>(std::ceil(seconds * 1000)));
  return stop_;
}

void HokuyoDriverActor::run() {
  hokuyo_detail::EventLog log(options_.device);
  ScipClient client(options_.client);
  double delay = options_.retry_initial_s;
  bool in_outage = false;
  const auto note = [this](const std::string& error) {
    std::lock_guard lock(stats_mutex_);
    stats_.last_error = error;
  };
  while (!stop_) {
    ByteLink link;
    try {
      link = ByteLink::open(options_.device, options_.baud);
    } catch (const LinkError& e) {
      {
        std::lock_guard lock(stats_mutex_);
        ++stats_.open_failures;
        stats_.last_error = e.what();
      }
      if (!in_outage)
        log.always(std::string("cannot open: ") + e.what() + "; retrying every " +
                   hokuyo_detail::seconds(delay) + " s and up to " +
                   hokuyo_detail::seconds(options_.retry_max_s) + " s");
      in_outage = true;
      if (waitOrStop(delay)) break;
      delay = std::min(2 * delay, options_.retry_max_s);
      continue;
    }
    std::string reason;
    std::int64_t scans_at_open = client.counters().scans;
    // Does what the client asks; false when the link must be dropped.
    const auto handle = [&](ScipClient::Output&& out, Nanos read_at) {
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
      if (!out.send.empty()) link.writeAll(out.send);
      if (out.reconnect) reason = out.reconnect_reason;
      return !out.reconnect;
    };
    try {
      handle(client.connected(ctx_->now()), steadyNow());
      std::string bytes;
      while (!stop_) {
        pollfd fds[2] = {{link.fd(), POLLIN, 0}, {wake_fd_, POLLIN, 0}};
        ::poll(fds, 2, 50);
        bytes.clear();
        if (fds[0].revents) link.readSome(bytes);
        const Nanos read_at = steadyNow();
        const Nanos now = ctx_->now();
        if (!bytes.empty() && !handle(client.received(bytes, now), read_at)) break;
        if (!handle(client.tick(now), read_at)) break;
        if (in_outage && client.state() == ScipClient::State::kStreaming) {
          log.always("connected, streaming");
          in_outage = false;
        }
      }
    } catch (const LinkError& e) {
      reason = e.what();
    }
    const bool worked = client.counters().scans > scans_at_open;
    client.disconnected();
    link.close();
    {
      std::lock_guard lock(stats_mutex_);
      stats_.client = client.counters();
      if (client.parameters()) stats_.model = client.parameters()->model;
    }
    if (stop_) break;
    note(reason);
    if (worked) delay = options_.retry_initial_s;
    {
      std::lock_guard lock(stats_mutex_);
      ++stats_.reconnects;
    }
    log.always(reason + "; reconnecting in " + hokuyo_detail::seconds(delay) + " s");
    in_outage = true;
    if (waitOrStop(delay)) break;
    delay = std::min(2 * delay, options_.retry_max_s);
  }
  std::lock_guard lock(stats_mutex_);
  stats_.client = client.counters();
  if (client.parameters()) stats_.model = client.parameters()->model;
  stats_.cpu_s = hokuyo_detail::threadCpuSeconds();
}

void HokuyoDriverActor::publish(const LaserReading& r) {
  auto loan =
      scan_pub_.loan(r.ranges.size() * sizeof(float) * (r.intensities.empty() ? 1 : 2) + 256);
  auto b = loan.builder();
  setHeader(b.initHeader(), r.stamp_ns, options_.frame_id, scan_pub_.nextSeq());
  b.setAngleMin(r.angle_min);
  b.setAngleIncrement(r.angle_increment);
  b.setRangeMin(r.range_min);
  b.setRangeMax(r.range_max);
  b.setScanTimeS(r.scan_time);
  b.setMountX(static_cast<float>(options_.mount[0]));
  b.setMountY(static_cast<float>(options_.mount[1]));
  b.setMountTheta(static_cast<float>(options_.mount[2]));
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

void HokuyoDriverActor::summarize(Summary& out) const {
  std::lock_guard lock(stats_mutex_);
  const auto& s = stats_;
  out["scans_published"] = s.published;
  out["sessions"] = s.client.sessions;
  out["reconnects"] = s.reconnects;
  out["open_failures"] = s.open_failures;
  out["bad_replies"] = s.client.bad_replies;
  out["refusals"] = s.client.refusals;
  out["garbage_bytes"] = static_cast<std::int64_t>(s.client.garbage_bytes);
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
  out["last_error"] = s.last_error;
}

TESSERA_REGISTER_ACTOR("hokuyo_scip", HokuyoDriverActor, HokuyoDriverOptions,
                       "Hokuyo URG/UTM laser over SCIP 2.0 (serial, USB-ACM or TCP)");

}  // namespace tessera::drivers
