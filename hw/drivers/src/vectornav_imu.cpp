// VectorNavImu: see vectornav_imu.hpp.
#include <tessera/drivers/session_text.hpp>
#include <tessera/drivers/vectornav_imu.hpp>

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <stdexcept>

namespace tessera::drivers {

namespace vectornav_imu_detail {

/// The VN-100's rates that termios has (128000 has no constant), the factory rate first.
constexpr std::array<int, 8> kSearch = {115200, 9600, 19200, 38400, 57600, 230400, 460800, 921600};
constexpr int kTries = 3;

int integer(const std::string& s) {
  int v = -1;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  return ec == std::errc() && end == s.data() + s.size() ? v : -1;
}

}  // namespace vectornav_imu_detail

VectorNavImu::VectorNavImu(VectorNavOptions options, int session_baud)
    : options_(options), session_baud_(session_baud), type_(vn::asyncType(options.output)) {
  namespace d = vectornav_imu_detail;
  const auto& o = options_;
  const auto& rates = vn::outputRates();
  if (std::find(rates.begin(), rates.end(), o.rate_hz) == rates.end())
    throw std::invalid_argument(
        "rate_hz must be one of the VN-100's output rates 1, 2, 4, 5, 10, 20, 25, 40, 50, 100, "
        "200, not " +
        std::to_string(o.rate_hz));
  if (std::find(d::kSearch.begin(), d::kSearch.end(), session_baud) == d::kSearch.end())
    throw std::invalid_argument(
        "baud must be a VN-100 rate: 9600, 19200, 38400, 57600, 115200, 230400, 460800 or "
        "921600 (its 128000 has no termios constant), not " +
        std::to_string(session_baud));
  if (!(o.reply_timeout_s > 0) || !std::isfinite(o.reply_timeout_s))
    throw std::invalid_argument("reply_timeout_s must be finite and > 0");
  if (o.silence_periods < 1) throw std::invalid_argument("silence_periods must be at least 1");
  // 10 bits a byte on the line (8N1).
  const std::size_t bytes = vn::lineBytes(type_);
  if (static_cast<std::size_t>(o.rate_hz) * bytes * 10 > static_cast<std::size_t>(session_baud))
    throw std::invalid_argument(
        "baud " + std::to_string(session_baud) + " cannot carry rate_hz " +
        std::to_string(o.rate_hz) + " of " + (type_ == vn::kTypeImu ? "VNIMU" : "VNYMR") +
        " lines (up to " + std::to_string(bytes) + " bytes each): raise baud or lower rate_hz");
  search_.push_back(session_baud);
  for (const int b : d::kSearch)
    if (b != session_baud) search_.push_back(b);
}

VectorNavImu::Counters VectorNavImu::counters() const {
  Counters c = counters_;
  c.garbage_bytes = garbage_before_ + splitter_.skippedBytes();
  return c;
}

std::string VectorNavImu::model() const {
  if (model_.empty()) return "";
  return serial_.empty() ? model_ : model_ + ", serial " + serial_;
}

std::string VectorNavImu::stepName(Step s) const {
  switch (s) {
    case Step::kModel:
      return "read model (VNRRG,01)";
    case Step::kSerial:
      return "read serial number (VNRRG,03)";
    case Step::kBaud:
      return "set baud rate (VNWRG,05," + std::to_string(session_baud_) + ")";
    case Step::kType:
      return "set output type (VNWRG,06," + std::to_string(type_) + ")";
    case Step::kRate:
      return "set output rate (VNWRG,07," + std::to_string(options_.rate_hz) + ")";
    default:
      return "stream";
  }
}

void VectorNavImu::send(ImuOutput& out, Step step, std::int64_t now_ns) {
  if (step != step_) tries_ = 0;
  step_ = step;
  ++tries_;
  switch (step) {
    case Step::kModel:
      out.send += vn::readRegister(vn::kModelRegister);
      break;
    case Step::kSerial:
      out.send += vn::readRegister(vn::kSerialRegister);
      break;
    case Step::kBaud:
      out.send += vn::writeRegister(vn::kBaudRegister, std::to_string(session_baud_));
      break;
    case Step::kType:
      out.send += vn::writeRegister(vn::kTypeRegister, std::to_string(type_));
      break;
    case Step::kRate:
      out.send += vn::writeRegister(vn::kRateRegister, std::to_string(options_.rate_hz));
      break;
    default:
      break;
  }
  deadline_ns_ = now_ns + nanosOf(options_.reply_timeout_s);
}

void VectorNavImu::next(ImuOutput& out, std::int64_t now_ns) {
  switch (step_) {
    case Step::kModel:
      return send(out, Step::kSerial, now_ns);
    case Step::kSerial:
      if (search_[search_at_] != session_baud_) return send(out, Step::kBaud, now_ns);
      return send(out, Step::kType, now_ns);
    case Step::kBaud:
      return send(out, Step::kType, now_ns);
    case Step::kType:
      return send(out, Step::kRate, now_ns);
    case Step::kRate:
      step_ = Step::kStreaming;
      ++counters_.sessions;
      deadline_ns_ = now_ns + nanosOf(silenceSeconds());
      out.events.push_back(
          "streaming: " + model() + ", " + (type_ == vn::kTypeImu ? "VNIMU" : "VNYMR") + " at " +
          std::to_string(options_.rate_hz) + " Hz, " + std::to_string(session_baud_) + " baud");
      return;
    default:
      return;
  }
}

void VectorNavImu::fail(ImuOutput& out, const std::string& why) {
  out.reconnect = true;
  out.reconnect_reason = why;
  out.events.push_back(why);
  disconnected();
}

void VectorNavImu::disconnected() {
  garbage_before_ += splitter_.skippedBytes();
  splitter_ = vn::LineSplitter();
  step_ = Step::kIdle;
  heard_ = false;
}

ImuOutput VectorNavImu::connected(std::int64_t now_ns) {
  disconnected();
  search_at_ = 0;  // the port opens at openBaud()
  ImuOutput out;
  send(out, Step::kModel, now_ns);
  return out;
}

void VectorNavImu::bad(const vn::Problem& p, ImuOutput& out) {
  switch (p.fault) {
    case vn::Fault::kTruncated:
      ++counters_.truncated;
      break;
    case vn::Fault::kChecksum:
      ++counters_.bad_checksum;
      break;
    case vn::Fault::kNotFinite:
      ++counters_.not_finite;
      break;
    default:
      ++counters_.malformed;
      break;
  }
  out.events.push_back(std::string("line dropped (") + vn::faultName(p.fault) + "): " + p.what);
}

ImuOutput VectorNavImu::received(std::string_view bytes, std::int64_t now_ns) {
  ImuOutput out;
  if (step_ == Step::kIdle) return out;
  for (const auto& line : splitter_.feed(bytes)) {
    vn::Problem p;
    std::optional<vn::Message> m;
    if (line.cut)
      p = {vn::Fault::kTruncated, "a line cut after " + std::to_string(line.text.size()) +
                                      " bytes (a new '$' came, or no line end)"};
    else
      m = vn::parseLine(line.text, p);
    if (!m) {
      // While looking for the device's rate, bad lines are what another rate sounds like.
      if (step_ == Step::kModel && !heard_)
        garbage_before_ += line.text.size();
      else
        bad(p, out);
      continue;
    }
    onMessage(*m, line.tail, now_ns, out);
    if (out.reconnect) break;
  }
  return out;
}

void VectorNavImu::onMessage(const vn::Message& m, std::size_t tail, std::int64_t now_ns,
                             ImuOutput& out) {
  namespace d = vectornav_imu_detail;
  heard_ = true;
  if (m.header == "VNYMR" || m.header == "VNIMU") {
    vn::Problem p;
    const auto s = vn::decodeSample(m, p);
    if (!s) return bad(p, out);
    if (step_ != Step::kStreaming) return;  // the output from before ours was set
    ImuReading r;
    r.received_ns = now_ns;
    // The line's first byte: `tail` bytes before the last one read, 10 bits each (8N1).
    const double line_s = static_cast<double>(tail) * 10.0 / search_[search_at_];
    r.stamp_ns = std::max(now_ns - nanosOf(line_s), last_stamp_ns_ + 1);
    last_stamp_ns_ = r.stamp_ns;
    const vn::Rep103 rep = vn::toRep103(*s);
    r.gyro = rep.gyro;
    r.accel = rep.accel;
    ++counters_.samples;
    deadline_ns_ = now_ns + nanosOf(silenceSeconds());
    out.samples.push_back(r);
    return;
  }
  if (m.header == "VNERR") {
    ++counters_.device_errors;
    const int code = m.fields.empty() ? -1 : d::integer(m.fields[0]);
    const std::string what = "error " + (m.fields.empty() ? std::string("?") : m.fields[0]) + " (" +
                             vn::errorName(code) + ")";
    if (step_ == Step::kStreaming) {
      out.events.push_back("the VN-100 reports " + what);
      return;
    }
    return fail(out, "the VN-100 refused " + stepName(step_) + ": " + what);
  }
  if (m.header != "VNRRG" && m.header != "VNWRG") return;  // VNYPR, other outputs: not ours
  int reg = 0;
  bool write = false;
  switch (step_) {
    case Step::kModel:
      reg = vn::kModelRegister;
      break;
    case Step::kSerial:
      reg = vn::kSerialRegister;
      break;
    case Step::kBaud:
      reg = vn::kBaudRegister;
      write = true;
      break;
    case Step::kType:
      reg = vn::kTypeRegister;
      write = true;
      break;
    case Step::kRate:
      reg = vn::kRateRegister;
      write = true;
      break;
    default:
      return;  // a late reply to an earlier session's command
  }
  // A reply to another command (one sent again, or an earlier step's): not this step's.
  if ((m.header == "VNWRG") != write || m.fields.empty() || d::integer(m.fields[0]) != reg) return;
  if (m.fields.size() != 2)
    return fail(out, "the VN-100 answered " + stepName(step_) + " with " +
                         std::to_string(m.fields.size() - 1) + " values, not 1");
  const std::string& value = m.fields[1];
  if (!write) {
    if (value.empty()) return fail(out, "the VN-100 answered " + stepName(step_) + " with nothing");
    (step_ == Step::kModel ? model_ : serial_) = value;
    return next(out, now_ns);
  }
  const int wanted = step_ == Step::kBaud   ? session_baud_
                     : step_ == Step::kType ? type_
                                            : options_.rate_hz;
  if (d::integer(value) != wanted)
    return fail(out, "the VN-100 answered " + stepName(step_) + " with '" + value + "'");
  if (step_ == Step::kBaud) {  // it answered at the old rate and switches now; the port follows
    out.switch_baud = session_baud_;
    search_at_ = 0;
  }
  next(out, now_ns);
}

ImuOutput VectorNavImu::tick(std::int64_t now_ns) {
  ImuOutput out;
  if (step_ == Step::kIdle || now_ns <= deadline_ns_) return out;
  const int baud = search_[search_at_];
  if (step_ == Step::kStreaming) {
    fail(out, "no good sample for " + decimal(silenceSeconds()) + " s (" +
                  std::to_string(options_.silence_periods) + " periods at " +
                  std::to_string(options_.rate_hz) + " Hz)");
    return out;
  }
  if (step_ == Step::kModel && !heard_) {  // nothing sensible at this rate: the next one
    if (search_at_ + 1 < search_.size()) {
      ++search_at_;
      out.switch_baud = search_[search_at_];
      out.events.push_back("no reply at " + std::to_string(baud) + " baud; trying " +
                           std::to_string(out.switch_baud));
      tries_ = 0;
      send(out, Step::kModel, now_ns);
      return out;
    }
    fail(out, "no reply to " + stepName(step_) +
                  " at any baud rate (9600 .. 921600): is a VN-100 on this port, and powered?");
    return out;
  }
  const std::string what = "no reply to " + stepName(step_) + " within " +
                           decimal(options_.reply_timeout_s) + " s at " + std::to_string(baud) +
                           " baud";
  if (tries_ < vectornav_imu_detail::kTries) {
    out.events.push_back(what + "; sending it again");
    send(out, step_, now_ns);
    return out;
  }
  fail(out, what + " (" + std::to_string(tries_) + " tries)");
  return out;
}

}  // namespace tessera::drivers
