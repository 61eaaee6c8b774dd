#include <tessera/drivers/laser_driver_loop.hpp>

#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>

#include <algorithm>
#include <cmath>

namespace tessera::drivers {

LaserDriverLoop::LaserDriverLoop(std::string name, DeviceLinkOptions link, LaserSession& session,
                                 ActorContext& ctx, Publisher<msg::LaserScan> scan,
                                 std::string frame_id, std::vector<double> mount)
    : session_(session), scan_pub_(scan), frame_id_(std::move(frame_id)), mount_(std::move(mount)) {
  DeviceHooks h;
  h.open_baud = [this](int configured) { return session_.openBaud(configured); };
  h.connected = [this](Nanos now) { return take(session_.connected(now), steadyNow()); };
  h.received = [this](std::string_view bytes, Nanos now, Nanos read_at) {
    return take(session_.received(bytes, now), read_at);
  };
  h.tick = [this](Nanos now) { return take(session_.tick(now), steadyNow()); };
  h.disconnected = [this] {
    session_.disconnected();
    std::lock_guard lock(stats_mutex_);
    stats_.session = session_.counters();
    stats_.model = session_.model();
  };
  h.streaming = [this] { return session_.streaming(); };
  h.progress = [this] { return session_.counters().scans; };
  loop_ = std::make_unique<DeviceLoop>(std::move(name), std::move(link), std::move(h), ctx);
}

DeviceStep LaserDriverLoop::take(SessionOutput&& out, Nanos read_at) {
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
  {
    std::lock_guard lock(stats_mutex_);
    stats_.session = session_.counters();
    stats_.model = session_.model();
  }
  DeviceStep step;
  step.switch_baud = out.switch_baud;
  step.send = std::move(out.send);
  step.events = std::move(out.events);
  step.reconnect = out.reconnect;
  step.reconnect_reason = std::move(out.reconnect_reason);
  return step;
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
  loop_->summarize(out);
  std::lock_guard lock(stats_mutex_);
  const auto& s = stats_;
  out["scans_published"] = s.published;
  out["sessions"] = s.session.sessions;
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
  out["model"] = s.model;
}

}  // namespace tessera::drivers

namespace tessera::drivers {

LaserDriverActor::LaserDriverActor(std::string name, DeviceLinkOptions link, std::string frame_id,
                                   std::vector<double> mount)
    : name_(std::move(name)),
      link_(std::move(link)),
      frame_id_(std::move(frame_id)),
      mount_(std::move(mount)) {
  checkLinkOptions(name_, link_);
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
