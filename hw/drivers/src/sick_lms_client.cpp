// SickLmsClient: see sick_lms_client.hpp.
#include <tessera/drivers/session_text.hpp>
#include <tessera/drivers/sick_lms_client.hpp>

#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

namespace tessera::drivers {

namespace sick_client_detail {

constexpr std::array<int, 4> kSearch = {9600, 19200, 38400, 500000};

}  // namespace sick_client_detail

using sick_client_detail::kSearch;

SickLmsClient::SickLmsClient(SickLmsClientOptions options, int session_baud)
    : options_(std::move(options)), session_baud_(session_baud) {
  const auto& o = options_;
  if (!sick::baudMode(session_baud))
    throw std::invalid_argument("the LMS runs at 9600, 19200, 38400 or 500000 baud, not " +
                                std::to_string(session_baud));
  if (o.angle_deg != 100 && o.angle_deg != 180)
    throw std::invalid_argument("angle_deg must be 100 or 180, got " + std::to_string(o.angle_deg));
  resolution_centideg_ = static_cast<int>(std::lround(o.resolution_deg * 100));
  if (!(resolution_centideg_ == 25 || resolution_centideg_ == 50 || resolution_centideg_ == 100) ||
      std::abs(o.resolution_deg * 100 - resolution_centideg_) > 1e-6)
    throw std::invalid_argument("resolution_deg must be 0.25, 0.5 or 1");
  if (resolution_centideg_ == 25 && o.angle_deg != 100)
    throw std::invalid_argument("resolution_deg 0.25 needs angle_deg 100");
  if (o.units != "mm" && o.units != "cm")
    throw std::invalid_argument("units must be mm or cm, got '" + o.units + "'");
  if (!(o.reply_timeout_s > 0) || !(o.scan_timeout_s > 0) || !std::isfinite(o.reply_timeout_s) ||
      !std::isfinite(o.scan_timeout_s))
    throw std::invalid_argument("reply_timeout_s and scan_timeout_s must be > 0");
  beams_ = static_cast<std::size_t>(o.angle_deg * 100 / resolution_centideg_ + 1);
}

int SickLmsClient::openBaud(int) {
  // The session rate first (the LMS keeps it while powered), then the others from 9600.
  const int k = attempt_ % static_cast<int>(kSearch.size() + 1);
  link_baud_ = k == 0 ? session_baud_ : kSearch[static_cast<std::size_t>(k - 1)];
  return link_baud_;
}

std::string SickLmsClient::model() const {
  return "SICK LMS2xx, " + std::to_string(options_.angle_deg) + " deg at " +
         decimal(options_.resolution_deg) + " deg, " + options_.units;
}

SessionCounters SickLmsClient::counters() const {
  SessionCounters c = counters_;
  c.garbage_bytes = garbage_before_ + parser_.skippedBytes();
  return c;
}

const char* SickLmsClient::stepName(Step s) {
  switch (s) {
    case Step::kStop:
      return "stop streaming (0x20 0x25)";
    case Step::kBaud:
      return "switch baud (0x20)";
    case Step::kVariant:
      return "variant (0x3B)";
    case Step::kReadConfig:
      return "read configuration (0x74)";
    case Step::kInstall:
      return "installation mode (0x20 0x00)";
    case Step::kWriteConfig:
      return "write configuration (0x77)";
    case Step::kStart:
      return "stream scans (0x20 0x24)";
    default:
      return "scan";
  }
}

void SickLmsClient::send(SessionOutput& out, Step step, const std::string& payload,
                         std::int64_t now_ns) {
  step_ = step;
  out.send += sick::frame(sick::kToSensor, payload);
  deadline_ns_ = now_ns + nanosOf(options_.reply_timeout_s);
}

void SickLmsClient::fail(SessionOutput& out, const std::string& why) {
  out.reconnect = true;
  out.reconnect_reason = why;
  out.events.push_back(why);
  disconnected();
}

void SickLmsClient::disconnected() {
  if (step_ != Step::kStreaming && step_ != Step::kIdle) ++attempt_;  // try the next rate
  garbage_before_ += parser_.skippedBytes();
  parser_ = sick::TelegramParser();
  step_ = Step::kIdle;
  session_items_ = 0;
}

SessionOutput SickLmsClient::connected(std::int64_t now_ns) {
  parser_ = sick::TelegramParser();
  session_items_ = 0;
  SessionOutput out;
  send(out, Step::kStop, sick::modeCommand(0x25), now_ns);
  return out;
}

SessionOutput SickLmsClient::received(std::string_view bytes, std::int64_t now_ns) {
  SessionOutput out;
  if (step_ == Step::kIdle) return out;
  for (const auto& item : parser_.feed(bytes)) {
    ++session_items_;
    if (item.kind == sick::TelegramParser::Item::Kind::kNak && step_ != Step::kStreaming) {
      ++counters_.refusals;
      fail(out, std::string("the LMS refused (NAK) ") + stepName(step_));
    } else if (item.kind == sick::TelegramParser::Item::Kind::kTelegram) {
      onTelegram(item.telegram, now_ns, out);
    }
    if (out.reconnect) break;
  }
  return out;
}

SessionOutput SickLmsClient::tick(std::int64_t now_ns) {
  SessionOutput out;
  if (step_ == Step::kIdle || now_ns <= deadline_ns_) return out;
  std::string why = step_ == Step::kStreaming
                        ? "no scan for " + decimal(options_.scan_timeout_s) + " s"
                        : std::string("no reply to ") + stepName(step_) + " within " +
                              decimal(options_.reply_timeout_s) + " s at " +
                              std::to_string(link_baud_) + " baud";
  const std::uint64_t noise = parser_.skippedBytes() + parser_.bufferedBytes();
  if (step_ != Step::kStreaming && session_items_ == 0 && noise > 0)
    why += " (" + std::to_string(noise) + " bytes that are not LMS telegrams: another rate?)";
  if (step_ != Step::kStreaming) why += "; trying the next baud rate";
  fail(out, why);
  return out;
}

void SickLmsClient::onTelegram(const sick::Telegram& t, std::int64_t now_ns, SessionOutput& out) {
  if ((t.address & 0x80u) == 0) return;  // an echo of our own telegram, or noise
  if (t.command == 0xB0) {
    if (step_ == Step::kStreaming || step_ == Step::kStart) onScan(t, now_ns, out);
    return;  // a stream an earlier session left running: the stop command is on its way
  }
  const auto ok = [&t](std::uint8_t command, std::uint8_t accept) {
    return t.command == command && !t.data.empty() &&
           static_cast<std::uint8_t>(t.data[0]) == accept;
  };
  const auto refused = [&](const std::string& what) {
    ++counters_.refusals;
    fail(out, std::string("the LMS refused ") + stepName(step_) + ": " + what);
  };
  switch (step_) {
    case Step::kStop:
    case Step::kBaud:
    case Step::kInstall:
    case Step::kStart:
      if (t.command != 0xA0) return;
      if (!ok(0xA0, 0x00))
        return refused("status " + std::to_string(static_cast<std::uint8_t>(
                                       t.data.empty() ? 0xFF : t.data[0])));
      if (step_ == Step::kBaud) {
        link_baud_ = session_baud_;
        out.switch_baud = session_baud_;
      }
      if (step_ == Step::kStart) {
        step_ = Step::kStreaming;
        deadline_ns_ = now_ns + nanosOf(options_.scan_timeout_s);
        ++counters_.sessions;
        attempt_ = 0;  // found it: next time, start from the session rate
        out.events.push_back("streaming: " + model() + ", " + std::to_string(link_baud_) + " baud");
        return;
      }
      return next(out, now_ns);
    case Step::kVariant:
      if (t.command != 0xBB) return;
      if (!ok(0xBB, 0x01))
        return refused("the variant " + std::to_string(options_.angle_deg) + " deg at " +
                       decimal(options_.resolution_deg) + " deg");
      return next(out, now_ns);
    case Step::kReadConfig:
      if (t.command != 0xF4) return;
      if (t.data.size() < sick::kUnitsByte + 2)
        return refused("a configuration of " + std::to_string(t.data.size()) + " bytes");
      config_ = t.data.substr(0, t.data.size() - 1);  // without the status byte
      return next(out, now_ns);
    case Step::kWriteConfig:
      if (t.command != 0xF7) return;
      if (!ok(0xF7, 0x01)) return refused("the configuration");
      return next(out, now_ns);
    default:
      return;
  }
}

void SickLmsClient::next(SessionOutput& out, std::int64_t now_ns) {
  const std::uint8_t units = options_.units == "mm" ? 1 : 0;
  switch (step_) {
    case Step::kStop:
      if (link_baud_ != session_baud_)
        return send(out, Step::kBaud, sick::modeCommand(*sick::baudMode(session_baud_)), now_ns);
      [[fallthrough]];
    case Step::kBaud:
      return send(out, Step::kVariant,
                  sick::variantCommand(options_.angle_deg, resolution_centideg_), now_ns);
    case Step::kVariant:
      return send(out, Step::kReadConfig, sick::configRequest(), now_ns);
    case Step::kReadConfig:
      if (static_cast<std::uint8_t>(config_[sick::kUnitsByte]) != units)
        return send(out, Step::kInstall, sick::modeCommand(0x00, "SICK_LMS"), now_ns);
      return send(out, Step::kStart, sick::modeCommand(0x24), now_ns);
    case Step::kInstall: {
      std::string config = config_;
      config[sick::kUnitsByte] = static_cast<char>(units);
      return send(out, Step::kWriteConfig, sick::configCommand(config), now_ns);
    }
    case Step::kWriteConfig:
      return send(out, Step::kStart, sick::modeCommand(0x24), now_ns);
    default:
      return;
  }
}

void SickLmsClient::onScan(const sick::Telegram& t, std::int64_t now_ns, SessionOutput& out) {
  std::string error;
  const auto scan = sick::decodeScan(t, error);
  if (scan && scan->values.size() != beams_)
    error = std::to_string(scan->values.size()) + " values, expected " + std::to_string(beams_);
  if (scan && error.empty() && scan->millimetres != (options_.units == "mm"))
    error =
        std::string("units ") + (scan->millimetres ? "mm" : "cm") + ", expected " + options_.units;
  if (!error.empty()) {
    ++counters_.bad_replies;
    out.events.push_back("scan dropped: " + error);
    return;
  }
  if (step_ == Step::kStart) {  // the acknowledgement was lost; the stream is on
    step_ = Step::kStreaming;
    ++counters_.sessions;
    attempt_ = 0;
  }
  LaserReading r;
  r.received_ns = now_ns;
  // 10 bits per byte on the line (8N1: start, 8 data, stop); 7 bytes of framing around the data.
  const double bytes = static_cast<double>(t.data.size() + 7);
  r.stamp_ns = now_ns - nanosOf(bytes * 10.0 / link_baud_);
  const double step = resolution_centideg_ * 0.01 * std::numbers::pi / 180;
  r.angle_min = static_cast<float>(-options_.angle_deg * 0.5 * std::numbers::pi / 180);
  r.angle_increment = static_cast<float>(step);
  const double unit = scan->millimetres ? 1e-3 : 1e-2;
  r.range_min = 0;
  r.range_max = static_cast<float>((sick::kFirstCode - 1) * unit);
  r.scan_time = static_cast<float>((100.0 / resolution_centideg_) / 75.0);  // interlaced sweeps
  constexpr float kInf = std::numeric_limits<float>::infinity();
  r.ranges.resize(beams_);
  for (std::size_t k = 0; k < beams_; ++k) {
    const std::uint16_t v = scan->values[k];
    r.ranges[k] = v >= sick::kFirstCode ? kInf : static_cast<float>(v * unit);
  }
  deadline_ns_ = now_ns + nanosOf(options_.scan_timeout_s);
  ++counters_.scans;
  out.scans.push_back(std::move(r));
}

}  // namespace tessera::drivers
