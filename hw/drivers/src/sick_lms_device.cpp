// SickLmsDevice: see sick_lms_device.hpp.
#include <tessera/drivers/sick_lms_device.hpp>

#include <algorithm>
#include <stdexcept>

namespace tessera::drivers {

namespace sick_device_detail {

constexpr std::int64_t kSweepNs = 1'000'000'000 / 75;  // one mirror revolution

std::string le16(int v) {
  std::string out;
  out += static_cast<char>(v & 0xFF);
  out += static_cast<char>((v >> 8) & 0xFF);
  return out;
}

}  // namespace sick_device_detail

using sick_device_detail::kSweepNs;
using sick_device_detail::le16;

SickLmsDevice::SickLmsDevice(LmsScanSource source, std::uint64_t seed)
    : source_(std::move(source)), rng_(seed), config_(33, '\0') {
  if (!source_) throw std::invalid_argument("SickLmsDevice: a scan source is required");
  config_[0] = 70;  // blanking [cm], as shipped; the rest zero, units cm
}

void SickLmsDevice::restart(std::int64_t now_ns) {
  baud_ = 9600;
  streaming_ = installation_ = false;
  outgoing_.clear();
  parser_ = sick::TelegramParser();
  line_free_ns_ = now_ns;
}

std::int64_t SickLmsDevice::lineTime(std::size_t bytes) const {
  return static_cast<std::int64_t>(bytes) * 10 * 1'000'000'000LL / baud_;
}

void SickLmsDevice::reply(const std::string& payload, std::int64_t now_ns) {
  if (faults_.silent) return;
  std::string bytes = sick::frame(sick::kFromSensor, payload);
  damage(bytes, faults_, rng_);
  const std::int64_t due =
      now_ns + static_cast<std::int64_t>(std::max(0.0, faults_.reply_delay_s) * 1e9);
  line_free_ns_ = std::max(line_free_ns_, due) + lineTime(bytes.size());
  outgoing_.append(due, std::move(bytes));
}

void SickLmsDevice::receive(std::string_view bytes, std::int64_t now_ns) {
  const std::uint64_t bad_before = parser_.badCrcs();
  for (const auto& item : parser_.feed(bytes)) {
    if (item.kind != sick::TelegramParser::Item::Kind::kTelegram) continue;
    if (item.telegram.address & 0x80u) continue;  // not for the sensor
    if (!faults_.silent) outgoing_.append(now_ns, std::string(1, static_cast<char>(sick::kAck)));
    handle(item.telegram, now_ns);
  }
  // A telegram whose CRC failed: the sensor says so.
  if (parser_.badCrcs() > bad_before && !faults_.silent)
    outgoing_.append(now_ns, std::string(1, static_cast<char>(sick::kNak)));
}

void SickLmsDevice::handle(const sick::Telegram& t, std::int64_t now_ns) {
  const std::string& d = t.data;
  const std::string status(1, static_cast<char>(status_));
  switch (t.command) {
    case 0x20: {
      if (d.empty()) return reply(std::string("\xA0\x02", 2) + status, now_ns);
      const auto mode = static_cast<std::uint8_t>(d[0]);
      if (mode == 0x00) {
        installation_ = d.substr(1) == "SICK_LMS";
        return reply(std::string("\xA0", 1) + (installation_ ? '\0' : '\x01') + status, now_ns);
      }
      if (mode == 0x24 || mode == 0x25) {
        streaming_ = mode == 0x24;
        installation_ = false;
        next_scan_ns_ = now_ns + kSweepNs;
        return reply(std::string("\xA0\x00", 2) + status, now_ns);
      }
      for (const int rate : {9600, 19200, 38400, 500000})
        if (sick::baudMode(rate) == mode) {
          reply(std::string("\xA0\x00", 2) + status, now_ns);
          outgoing_.changeBaudWhenSent(rate);  // after the reply has gone out at the old rate
          return;
        }
      return reply(std::string("\xA0\x02", 2) + status, now_ns);
    }
    case 0x3B: {
      if (d.size() != 4) return reply(std::string("\xBB\x00", 2) + status, now_ns);
      const int angle = static_cast<std::uint8_t>(d[0]) | (static_cast<std::uint8_t>(d[1]) << 8);
      const int res = static_cast<std::uint8_t>(d[2]) | (static_cast<std::uint8_t>(d[3]) << 8);
      const bool valid = (angle == 180 && (res == 100 || res == 50)) ||
                         (angle == 100 && (res == 100 || res == 50 || res == 25));
      if (valid) {
        angle_deg_ = angle;
        resolution_centideg_ = res;
      }
      return reply(std::string("\xBB", 1) + (valid ? '\x01' : '\0') + le16(angle_deg_) +
                       le16(resolution_centideg_) + status,
                   now_ns);
    }
    case 0x74:
      return reply(std::string("\xF4", 1) + config_ + status, now_ns);
    case 0x77: {
      const bool accepted = installation_ && d.size() == config_.size();
      if (accepted) config_ = d;
      return reply(std::string("\xF7", 1) + (accepted ? '\x01' : '\0') + config_ + status, now_ns);
    }
    default:
      // Unknown to this emulator: the LMS answers 0x92 "unknown telegram".
      return reply(std::string("\x92", 1) + status, now_ns);
  }
}

std::string SickLmsDevice::poll(std::int64_t now_ns) {
  const std::int64_t period = kSweepNs * (100 / resolution_centideg_);
  while (streaming_ && next_scan_ns_ <= now_ns && !faults_.silent) {
    const std::int64_t at = next_scan_ns_;
    next_scan_ns_ += period;
    if (line_free_ns_ > at) {  // the previous scan is still going out at this baud rate
      ++scans_skipped_;
      continue;
    }
    const auto mm = source_(angle_deg_, resolution_centideg_);
    sick::Scan s;
    s.millimetres = millimetres();
    s.status = status_;
    s.values.reserve(mm.size());
    for (const std::uint32_t r : mm) {
      const std::uint32_t v = r == 0 ? 8191u : (s.millimetres ? r : (r + 5) / 10);
      s.values.push_back(static_cast<std::uint16_t>(std::min<std::uint32_t>(v, 8191u)));
    }
    reply(sick::encodeScan(s), at);
    ++scans_sent_;
  }
  return outgoing_.take(now_ns, baud_);
}

std::optional<std::int64_t> SickLmsDevice::nextDue() const {
  std::optional<std::int64_t> due = outgoing_.nextDue();
  if (streaming_ && !faults_.silent && (!due || next_scan_ns_ < *due)) due = next_scan_ns_;
  return due;
}

}  // namespace tessera::drivers
