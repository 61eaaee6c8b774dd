// ScipClient: see scip_client.hpp.
#include <tessera/drivers/scip_client.hpp>
#include <tessera/drivers/session_text.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

namespace tessera::drivers {

namespace scip_client_detail {

// The scan command's echo without its remaining-scans count, which MD replies count down.
constexpr std::size_t kScanEchoPrefix = 13;

}  // namespace scip_client_detail

using scip_client_detail::kScanEchoPrefix;

ScipClient::ScipClient(ScipClientOptions options)
    : options_(options),
      clock_(24, 1'000'000, nanosOf(options.clock_window_s > 0 ? options.clock_window_s : 1)) {
  const auto& o = options_;
  if (o.cluster < 1 || o.cluster > 99)
    throw std::invalid_argument("cluster must be 1..99, got " + std::to_string(o.cluster));
  if (o.first_step < -1 || o.last_step < -1 || o.first_step > 9999 || o.last_step > 9999)
    throw std::invalid_argument("first_step and last_step must be -1 (the sensor's) or 0..9999");
  if (o.first_step >= 0 && o.last_step >= 0 && o.last_step < o.first_step)
    throw std::invalid_argument("last_step " + std::to_string(o.last_step) +
                                " is before first_step " + std::to_string(o.first_step));
  if (!(o.reply_timeout_s > 0) || !(o.scan_timeout_s > 0) || !(o.clock_window_s > 0) ||
      !std::isfinite(o.reply_timeout_s) || !std::isfinite(o.scan_timeout_s) ||
      !std::isfinite(o.clock_window_s))
    throw std::invalid_argument("reply_timeout_s, scan_timeout_s and clock_window_s must be > 0");
}

ScipClient::Counters ScipClient::counters() const {
  Counters c = counters_;
  c.garbage_bytes = garbage_before_ + parser_.skippedBytes();
  return c;
}

void ScipClient::send(Output& out, const std::string& command, std::int64_t now_ns) {
  out.send += command;
  waiting_for_ = command.substr(0, command.size() - 1);  // the echo: the line without its LF
  deadline_ns_ = now_ns + nanosOf(options_.reply_timeout_s);
}

void ScipClient::fail(Output& out, const std::string& why) {
  out.reconnect = true;
  out.reconnect_reason = why;
  out.events.push_back(why);
  disconnected();
}

ScipClient::Output ScipClient::connected(std::int64_t now_ns) {
  disconnected();
  Output out;
  state_ = State::kHandshake;
  send(out, "SCIP2.0\n", now_ns);
  return out;
}

void ScipClient::disconnected() {
  garbage_before_ += parser_.skippedBytes();
  parser_ = scip::ReplyParser();
  clock_.reset();  // the device may have restarted: its counter too
  state_ = State::kDisconnected;
  waiting_for_.clear();
  scan_echo_.clear();
  session_replies_ = 0;
}

ScipClient::Output ScipClient::received(std::string_view bytes, std::int64_t now_ns) {
  Output out;
  if (state_ == State::kDisconnected) return out;
  for (const auto& reply : parser_.feed(bytes)) {
    ++session_replies_;
    onReply(reply, now_ns, out);
    if (out.reconnect) break;
  }
  return out;
}

ScipClient::Output ScipClient::tick(std::int64_t now_ns) {
  Output out;
  if (state_ == State::kDisconnected || now_ns <= deadline_ns_) return out;
  std::string why =
      state_ == State::kStreaming
          ? "no scan for " + decimal(options_.scan_timeout_s) + " s"
          : "no reply to '" + waiting_for_ + "' within " + decimal(options_.reply_timeout_s) + " s";
  const std::uint64_t noise = parser_.skippedBytes() + parser_.bufferedBytes();
  if (state_ == State::kHandshake && noise > 0 && session_replies_ == 0)
    why += " (" + std::to_string(noise) +
           " bytes came that are not SCIP replies: wrong baud rate, or not a SCIP 2.0 device?)";
  else if (state_ == State::kHandshake && session_replies_ > 0)
    why += " (" + std::to_string(session_replies_) + " replies to other commands came)";
  fail(out, why);
  return out;
}

void ScipClient::onReply(const scip::Reply& reply, std::int64_t now_ns, Output& out) {
  if (state_ == State::kStreaming) {
    if (reply.echo.compare(0, kScanEchoPrefix, scan_echo_, 0, kScanEchoPrefix) == 0 &&
        reply.echo.size() == scan_echo_.size())
      onScan(reply, now_ns, out);
    return;  // anything else: an answer to nothing we asked
  }
  if (reply.echo != waiting_for_) return;  // e.g. scans of a stream an earlier session left on
  if (!reply.error.empty()) {
    ++counters_.bad_replies;
    return fail(out, "reply to '" + waiting_for_ + "': " + reply.error);
  }
  if (waiting_for_ == "SCIP2.0") {
    // 00: switched; 0E: already in SCIP 2.0.
    if (reply.status != "00" && reply.status != "0E")
      return fail(out, "SCIP2.0 refused with status " + reply.status);
    return send(out, "QT\n", now_ns);
  }
  if (waiting_for_ == "QT") {
    if (reply.status != "00") return fail(out, "QT refused with status " + reply.status);
    return send(out, "PP\n", now_ns);
  }
  if (waiting_for_ == "PP") {
    std::string error;
    parameters_ = scip::parseParameters(reply, error);
    if (!parameters_) return fail(out, error);
    return startScans(now_ns, out);
  }
  // The scan command's acknowledgement, or (if that was lost) its first scan.
  if (reply.status != "00" && reply.status != "99") {
    ++counters_.refusals;
    return fail(out, "'" + waiting_for_ + "' refused with status " + reply.status);
  }
  state_ = State::kStreaming;
  scan_echo_ = waiting_for_;
  deadline_ns_ = now_ns + nanosOf(options_.scan_timeout_s);
  ++counters_.sessions;
  out.events.push_back("streaming: " + parameters_->model + ", steps " + std::to_string(first_) +
                       ".." + std::to_string(last_) + ", " + std::to_string(parameters_->scan_rpm) +
                       " rpm");
  if (reply.status == "99") onScan(reply, now_ns, out);
}

void ScipClient::startScans(std::int64_t now_ns, Output& out) {
  const auto& p = *parameters_;
  first_ = options_.first_step >= 0 ? options_.first_step : p.first_step;
  last_ = options_.last_step >= 0 ? options_.last_step : p.last_step;
  if (first_ < p.first_step || last_ > p.last_step || last_ < first_)
    return fail(out, "steps " + std::to_string(first_) + ".." + std::to_string(last_) +
                         " are outside the sensor's " + std::to_string(p.first_step) + ".." +
                         std::to_string(p.last_step) + " (first_step, last_step)");
  const int cluster = options_.cluster == 1 ? 0 : options_.cluster;  // 0 and 1 both mean none
  send(out,
       options_.intensity ? scip::intensityCommand(first_, last_, cluster)
                          : scip::scanCommand(true, first_, last_, cluster),
       now_ns);
}

void ScipClient::onScan(const scip::Reply& reply, std::int64_t now_ns, Output& out) {
  if (reply.status == "00") return;  // a repeated acknowledgement
  if (reply.status != "99" && reply.error.empty()) {
    ++counters_.refusals;
    out.events.push_back("scan status " + reply.status + " (sensor error)");
    return;
  }
  const auto d = scip::decodeScan(reply, 3, options_.intensity);
  const auto& p = *parameters_;
  const std::size_t beams =
      static_cast<std::size_t>((last_ - first_ + options_.cluster) / options_.cluster);
  std::string error = d.error;
  if (error.empty() && d.scan->ranges.size() != beams)
    error = std::to_string(d.scan->ranges.size()) + " ranges, expected " + std::to_string(beams);
  if (!error.empty()) {
    ++counters_.bad_replies;
    out.events.push_back("scan dropped: " + error);
    return;
  }
  LaserReading r;
  r.received_ns = now_ns;
  r.stamp_ns = clock_.stamp(d.scan->timestamp_ms, now_ns);
  const double step = 2 * std::numbers::pi / p.steps_per_revolution;
  const double centre = (options_.cluster - 1) / 2.0;  // a merged beam looks between its steps
  r.angle_min = static_cast<float>((first_ + centre - p.front_step) * step);
  r.angle_increment = static_cast<float>(options_.cluster * step);
  r.range_min = static_cast<float>(p.min_range_mm * 1e-3);
  r.range_max = static_cast<float>(p.max_range_mm * 1e-3);
  r.scan_time = static_cast<float>(60.0 / p.scan_rpm);
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  constexpr float kInf = std::numeric_limits<float>::infinity();
  r.ranges.resize(beams);
  for (std::size_t k = 0; k < beams; ++k) {
    const std::uint32_t mm = d.scan->ranges[k];
    if (mm == 0)
      r.ranges[k] = options_.zero_is_no_return ? kInf : kNaN;
    else if (mm < static_cast<std::uint32_t>(p.min_range_mm))
      r.ranges[k] = kNaN;  // the sensor's error codes
    else
      r.ranges[k] = static_cast<float>(static_cast<double>(mm) * 1e-3);
  }
  r.intensities.assign(d.scan->intensities.begin(), d.scan->intensities.end());
  deadline_ns_ = now_ns + nanosOf(options_.scan_timeout_s);
  ++counters_.scans;
  out.scans.push_back(std::move(r));
}

}  // namespace tessera::drivers
