// CreateBase: see create_base.hpp.
#include <tessera/drivers/create_base.hpp>
#include <tessera/drivers/session_text.hpp>

#include <cmath>
#include <stdexcept>

namespace tessera::drivers {

namespace create_base_detail {

bool sameSensors(const oi::SensorFrame& a, const oi::SensorFrame& b) {
  return a.bump_left == b.bump_left && a.bump_right == b.bump_right &&
         a.wheel_drop_left == b.wheel_drop_left && a.wheel_drop_right == b.wheel_drop_right &&
         a.anyCliff() == b.anyCliff() && a.charging_state == b.charging_state;
}

}  // namespace create_base_detail

CreateBase::CreateBase(CreateBaseOptions options) : options_(options) {
  const auto& o = options_;
  const auto positive = [](double v) { return v > 0 && std::isfinite(v); };
  if (!positive(o.wheel_base_m) || !positive(o.wheel_radius_m) ||
      !positive(o.counts_per_revolution))
    throw std::invalid_argument(
        "wheel_base_m, wheel_radius_m and counts_per_revolution must be > 0");
  if (!positive(o.max_speed_m_s) || o.max_speed_m_s > 0.5)
    throw std::invalid_argument("max_speed_m_s must be in (0, 0.5] (the OI's limit)");
  if (!positive(o.watchdog_s) || !positive(o.frame_timeout_s))
    throw std::invalid_argument("watchdog_s and frame_timeout_s must be > 0");
}

CreateBase::Counters CreateBase::counters() const {
  Counters c = counters_;
  c.garbage_bytes = garbage_before_ + parser_.skippedBytes();
  c.bad_frames = static_cast<std::int64_t>(bad_before_ + parser_.badFrames());
  return c;
}

BaseOutput CreateBase::connected(std::int64_t now_ns) {
  disconnected();
  connected_ = true;
  BaseOutput out;
  out.send += static_cast<char>(oi::kStart);
  out.send += static_cast<char>(options_.full_mode ? oi::kFull : oi::kSafe);
  drive(out, 0, 0);
  out.send += oi::streamCommand(oi::streamedPackets());
  last_frame_ns_ = now_ns;  // the first frame is due within frame_timeout_s
  return out;
}

void CreateBase::disconnected() {
  garbage_before_ += parser_.skippedBytes();
  bad_before_ += parser_.badFrames();
  parser_ = oi::StreamParser(oi::frameBodyBytes(oi::streamedPackets()));
  left_.reset();
  right_.reset();
  connected_ = streaming_ = moving_ = false;
}

void CreateBase::drive(BaseOutput& out, double right_mm_s, double left_mm_s) {
  out.send += oi::driveDirect(right_mm_s, left_mm_s);
  moving_ = std::lround(right_mm_s) != 0 || std::lround(left_mm_s) != 0;
}

void CreateBase::stop(BaseOutput& out, const std::string& reason, std::int64_t now_ns) {
  drive(out, 0, 0);
  stop_reason_ = reason;
  out.events.push_back("stopped: " + reason);
  publishStatus(out, now_ns);
}

void CreateBase::publishStatus(BaseOutput& out, std::int64_t now_ns) {
  out.status.push_back({now_ns, sensors_, moving_, stop_reason_});
  last_status_ns_ = now_ns;
}

std::string CreateBase::blocked(double vx) const {
  const auto& s = sensors_;
  if (s.wheel_drop_left || s.wheel_drop_right) return "wheel drop";
  if ((s.bump_left || s.bump_right) && vx > 0)
    return std::string("bumper ") + (s.bump_left && s.bump_right ? "both"
                                     : s.bump_left               ? "left"
                                                                 : "right");
  if (s.anyCliff() && vx > 0) return "cliff";
  return "";
}

BaseOutput CreateBase::command(double vx, double omega, std::int64_t now_ns) {
  BaseOutput out;
  if (!connected_) return out;
  ++counters_.commands;
  last_command_ns_ = now_ns;
  if (!std::isfinite(vx) || !std::isfinite(omega)) {
    if (moving_) stop(out, "non-finite command", now_ns);
    return out;
  }
  if (const std::string why = blocked(vx); !why.empty()) {
    ++counters_.refused_commands;
    if (moving_) stop(out, why, now_ns);
    return out;
  }
  // Wheel speeds, scaled together so the curvature survives the speed limit.
  double right = vx + omega * options_.wheel_base_m / 2;
  double left = vx - omega * options_.wheel_base_m / 2;
  const double fastest = std::max(std::abs(right), std::abs(left));
  if (fastest > options_.max_speed_m_s) {
    right *= options_.max_speed_m_s / fastest;
    left *= options_.max_speed_m_s / fastest;
  }
  const bool was_stopped = !moving_;
  last_vx_ = vx;
  drive(out, right * 1000, left * 1000);
  if (was_stopped && moving_ && !stop_reason_.empty()) {
    stop_reason_.clear();
    publishStatus(out, now_ns);
  }
  return out;
}

BaseOutput CreateBase::received(std::string_view bytes, std::int64_t now_ns) {
  namespace d = create_base_detail;
  BaseOutput out;
  if (!connected_) return out;
  for (const auto& f : parser_.feed(bytes)) {
    ++counters_.frames;
    streaming_ = true;
    last_frame_ns_ = now_ns;
    const bool changed = !d::sameSensors(f, sensors_);
    sensors_ = f;
    out.ticks.push_back({now_ns, left_(f.left_counts), right_(f.right_counts)});
    if (moving_) {
      // The command that is running now may not run any more.
      if (const std::string why = blocked(last_vx_); !why.empty()) {
        ++counters_.safety_stops;
        stop(out, why, now_ns);
        continue;
      }
    }
    if (changed || now_ns - last_status_ns_ >= 500'000'000) publishStatus(out, now_ns);
  }
  return out;
}

BaseOutput CreateBase::tick(std::int64_t now_ns) {
  BaseOutput out;
  if (!connected_) return out;
  if (now_ns - last_frame_ns_ > nanosOf(options_.frame_timeout_s)) {
    out.reconnect = true;
    out.reconnect_reason = "no sensor frame for " + decimal(options_.frame_timeout_s) + " s";
    out.events.push_back(out.reconnect_reason);
    disconnected();
    return out;
  }
  if (moving_ && now_ns - last_command_ns_ > nanosOf(options_.watchdog_s)) {
    ++counters_.watchdog_stops;
    stop(out, "watchdog: no drive command for " + decimal(options_.watchdog_s) + " s", now_ns);
  }
  return out;
}

}  // namespace tessera::drivers
