// ScipDevice: see scip_device.hpp.
#include <tessera/drivers/scip_device.hpp>

#include <algorithm>
#include <cctype>
#include <stdexcept>

namespace tessera::drivers {

namespace {

bool digits(const std::string& s, std::size_t at, std::size_t n, int& out) {
  if (s.size() < at + n) return false;
  out = 0;
  for (std::size_t k = at; k < at + n; ++k) {
    if (!std::isdigit(static_cast<unsigned char>(s[k]))) return false;
    out = out * 10 + (s[k] - '0');
  }
  return true;
}

std::string twoDigits(int v) {
  return std::string(1, static_cast<char>('0' + v / 10)) + static_cast<char>('0' + v % 10);
}

}  // namespace

scip::SensorParameters ScipDevice::urg04lx() {
  scip::SensorParameters p;
  p.model = "URG-04LX(Hokuyo Automatic Co.,Ltd.)";
  p.min_range_mm = 20;
  p.max_range_mm = 5600;
  p.steps_per_revolution = 1024;
  p.first_step = 44;
  p.last_step = 725;
  p.front_step = 384;
  p.scan_rpm = 600;
  return p;
}

ScipDevice::ScipDevice(scip::SensorParameters parameters, ScanSource source, std::uint64_t seed)
    : params_(std::move(parameters)), source_(std::move(source)), rng_(seed) {
  if (!source_) throw std::invalid_argument("ScipDevice: a scan source is required");
}

void ScipDevice::restart(std::int64_t now_ns) {
  stream_.reset();
  laser_on_ = false;
  outgoing_.clear();
  line_.clear();
  clock_zero_ns_ = now_ns;
}

void ScipDevice::receive(std::string_view bytes, std::int64_t now_ns) {
  for (const char c : bytes) {
    if (c == '\r') continue;
    if (c != '\n') {
      if (line_.size() < 256) line_ += c;  // a runaway line is cut; its command is unknown
      continue;
    }
    const std::string line = std::move(line_);
    line_.clear();
    if (line.empty()) continue;
    ++commands_;
    if (!faults_.silent) command(line, now_ns);
  }
}

std::optional<ScipDevice::Stream> ScipDevice::parseScanCommand(const std::string& line,
                                                               std::string& status) const {
  const std::string kind = line.substr(0, 2);
  const bool continuous = kind == "MD" || kind == "MS" || kind == "ME";
  Stream s;
  s.echo = line;
  s.chars = kind[1] == 'S' ? 2 : 3;
  s.intensity = kind == "ME";
  const std::size_t length = continuous ? 15 : 12;
  int cluster = 0;
  if (line.size() != length || !digits(line, 2, 4, s.first) || !digits(line, 6, 4, s.last) ||
      !digits(line, 10, 2, cluster) ||
      (continuous && (!digits(line, 12, 1, s.interval) || !digits(line, 13, 2, s.remaining)))) {
    status = "0C";  // parameter error
    return std::nullopt;
  }
  s.cluster = std::max(cluster, 1);
  if (s.first < params_.first_step || s.first > params_.last_step) {
    status = "10";  // starting step out of range
    return std::nullopt;
  }
  if (s.last < s.first || s.last > params_.last_step) {
    status = "11";  // end step out of range
    return std::nullopt;
  }
  return s;
}

void ScipDevice::command(const std::string& line, std::int64_t now_ns) {
  using scip::encodeStatusReply;
  if (line == "SCIP2.0" || line == "BM" || line == "RS" || line == "QT") {
    if (line == "QT" || line == "RS") stream_.reset();
    laser_on_ = line == "BM" || (line != "QT" && line != "RS" && laser_on_);
    return queue(encodeStatusReply(line, "00"), now_ns);
  }
  if (line == "PP") return queue(scip::encodeParametersReply(params_), now_ns);
  if (line == "VV") {
    std::string out = encodeStatusReply(line, "00");
    out.pop_back();  // the information lines go before the empty line
    const std::vector<std::string> lines{"VEND:Hokuyo Automatic Co.,Ltd.", "PROD:" + params_.model,
                                         "FIRM:emulated", "PROT:SCIP 2.0", "SERI:H0000000"};
    for (const auto& l : lines) out += l + ';' + scip::checksum(l) + '\n';
    return queue(out + '\n', now_ns);
  }
  const std::string kind = line.substr(0, std::min<std::size_t>(2, line.size()));
  if (kind != "MD" && kind != "MS" && kind != "ME" && kind != "GD" && kind != "GS")
    return queue(encodeStatusReply(line, "0E"), now_ns);
  std::string status;
  auto s = parseScanCommand(line, status);
  if (!s) return queue(encodeStatusReply(line, status), now_ns);
  laser_on_ = true;
  if (kind[0] == 'G') {  // one scan, now
    const auto scan = source_();
    if (!scan) {
      source_ended_ = true;
      return;
    }
    return queue(scanReply(line, "00", *s, *scan, now_ns), now_ns);
  }
  queue(encodeStatusReply(line, "00"), now_ns);
  s->next_ns = now_ns;
  stream_ = std::move(s);
}

std::string ScipDevice::scanReply(const std::string& echo, const std::string& status,
                                  const Stream& s, const EmulatedScan& scan, std::int64_t now_ns) {
  const std::size_t steps = static_cast<std::size_t>(params_.last_step - params_.first_step + 1);
  if (scan.ranges_mm.size() != steps)
    throw std::invalid_argument("ScipDevice: a scan of " + std::to_string(scan.ranges_mm.size()) +
                                " ranges, the sensor has " + std::to_string(steps) + " steps");
  const std::uint32_t max_value = s.chars == 2 ? 4095u : 262143u;
  std::vector<std::uint32_t> values;
  for (int step = s.first; step <= s.last; step += s.cluster) {
    // A merged beam is the nearest valid reading of its steps, as the sensor reports it.
    std::uint32_t best = 0;
    std::uint32_t best_intensity = 0;
    for (int k = step; k < std::min(step + s.cluster, s.last + 1); ++k) {
      const auto i = static_cast<std::size_t>(k - params_.first_step);
      const std::uint32_t r = scan.ranges_mm[i];
      const bool valid = r >= static_cast<std::uint32_t>(params_.min_range_mm);
      if (k == step ||
          (valid && (best < static_cast<std::uint32_t>(params_.min_range_mm) || r < best))) {
        best = r;
        best_intensity = i < scan.intensities.size() ? scan.intensities[i] : 0;
      }
    }
    values.push_back(std::min(best, max_value));
    if (s.intensity) values.push_back(std::min(best_intensity, max_value));
  }
  const std::uint32_t stamp =
      scan.sensor_ms ? *scan.sensor_ms
                     : static_cast<std::uint32_t>((now_ns - clock_zero_ns_) / 1'000'000);
  return scip::encodeScanReply(echo, status, stamp & 0xFFFFFFu, values, s.chars);
}

void ScipDevice::queue(std::string bytes, std::int64_t now_ns) {
  if (faults_.silent) return;
  damage(bytes, faults_, rng_, '\n');
  outgoing_.append(now_ns + static_cast<std::int64_t>(std::max(0.0, faults_.reply_delay_s) * 1e9),
                   std::move(bytes));
}

std::string ScipDevice::poll(std::int64_t now_ns) {
  const std::int64_t revolution = 60'000'000'000LL / params_.scan_rpm;
  while (stream_ && !source_ended_ && stream_->next_ns <= now_ns) {
    Stream& s = *stream_;
    const auto scan = source_();
    if (!scan) {
      source_ended_ = true;
      break;
    }
    const std::int64_t at = s.next_ns;
    s.next_ns += scan->period_ns > 0 ? scan->period_ns : revolution;
    if (s.skipped < s.interval) {
      ++s.skipped;
      continue;
    }
    s.skipped = 0;
    std::string echo = s.echo;
    if (s.remaining > 0) {
      --s.remaining;
      echo.replace(13, 2, twoDigits(s.remaining));
    }
    queue(scanReply(echo, "99", s, *scan, at), at);
    ++scans_sent_;
    if (s.echo.substr(13, 2) != "00" && s.remaining == 0) stream_.reset();
  }
  return outgoing_.take(now_ns);
}

std::optional<std::int64_t> ScipDevice::nextDue() const {
  std::optional<std::int64_t> due = outgoing_.nextDue();
  if (stream_ && !source_ended_ && (!due || stream_->next_ns < *due)) due = stream_->next_ns;
  return due;
}

}  // namespace tessera::drivers
