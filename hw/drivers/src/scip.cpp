// SCIP 2.0 encoding and reply parsing: see scip.hpp.
#include <tessera/drivers/scip.hpp>

#include <algorithm>
#include <cctype>
#include <stdexcept>

namespace tessera::drivers::scip {

char checksum(std::string_view line) {
  unsigned sum = 0;
  for (const char c : line) sum += static_cast<unsigned char>(c);
  return static_cast<char>((sum & 0x3Fu) + 0x30u);
}

std::string encode(std::uint32_t value, int chars) {
  if (chars < 1 || chars > 4)
    throw std::invalid_argument("scip::encode: chars must be 1..4, got " + std::to_string(chars));
  if (value >> (6 * chars))
    throw std::invalid_argument("scip::encode: " + std::to_string(value) + " does not fit in " +
                                std::to_string(chars) + " characters");
  std::string out(static_cast<std::size_t>(chars), '0');
  for (int k = chars - 1; k >= 0; --k) {
    out[static_cast<std::size_t>(k)] = static_cast<char>((value & 0x3Fu) + 0x30u);
    value >>= 6;
  }
  return out;
}

std::optional<std::uint32_t> decode(std::string_view chars) {
  if (chars.empty() || chars.size() > 4) return std::nullopt;
  std::uint32_t v = 0;
  for (const char c : chars) {
    const auto b = static_cast<unsigned char>(c);
    if (b < 0x30 || b > 0x6F) return std::nullopt;
    v = (v << 6) | (b - 0x30u);
  }
  return v;
}

namespace scip_detail {

std::string twoDigits(int v, const char* what, int hi) {
  if (v < 0 || v > hi)
    throw std::invalid_argument(std::string("scip::scanCommand: ") + what + " must be 0.." +
                                std::to_string(hi) + ", got " + std::to_string(v));
  return std::string(1, static_cast<char>('0' + v / 10)) + static_cast<char>('0' + v % 10);
}

std::string fourDigits(int v, const char* what) {
  if (v < 0 || v > 9999)
    throw std::invalid_argument(std::string("scip::scanCommand: ") + what +
                                " must be 0..9999, got " + std::to_string(v));
  std::string s = std::to_string(v);
  return std::string(4 - s.size(), '0') + s;
}

/// A line that can be the echo of a command: two upper-case letters, then printable ASCII.
bool looksLikeEcho(const std::string& line) {
  if (line.size() < 2) return false;
  if (!std::isupper(static_cast<unsigned char>(line[0])) ||
      !std::isupper(static_cast<unsigned char>(line[1])))
    return false;
  for (const char c : line)
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7E) return false;
  return true;
}

Reply buildReply(std::vector<std::string>& lines) {
  Reply r;
  r.echo = std::move(lines[0]);
  if (lines.size() < 2) {
    r.error = "no status line after the echo '" + r.echo + "'";
    return r;
  }
  const std::string& status = lines[1];
  if (status.size() != 3) {
    r.error = "status line '" + status + "' is not 2 characters and a checksum";
    return r;
  }
  r.status = status.substr(0, 2);
  if (checksum(r.status) != status[2]) {
    r.error = "status line '" + status + "': checksum mismatch";
    return r;
  }
  for (std::size_t k = 2; k < lines.size(); ++k) {
    const std::string& l = lines[k];
    if (l.size() < 2) {
      r.error = "line " + std::to_string(k + 1) + ": too short for data and a checksum";
      return r;
    }
    const std::string_view data(l.data(), l.size() - 1);
    // The information replies' "KEY:VALUE;" lines sum without the ';'.
    const bool info = r.echo == "PP" || r.echo == "VV" || r.echo == "II";
    const std::string_view summed =
        info && data.ends_with(';') ? data.substr(0, data.size() - 1) : data;
    if (checksum(summed) != l.back()) {
      r.error = "line " + std::to_string(k + 1) + ": checksum mismatch";
      return r;
    }
    r.payload.emplace_back(data);
  }
  return r;
}

}  // namespace scip_detail

std::string scanCommand(bool continuous, int first, int last, int cluster, int interval, int scans,
                        bool three_chars) {
  if (last < first)
    throw std::invalid_argument("scip::scanCommand: last step " + std::to_string(last) +
                                " is before the first " + std::to_string(first));
  std::string cmd = continuous ? (three_chars ? "MD" : "MS") : (three_chars ? "GD" : "GS");
  cmd += scip_detail::fourDigits(first, "first") + scip_detail::fourDigits(last, "last") +
         scip_detail::twoDigits(cluster, "cluster", 99);
  if (continuous) {
    if (interval < 0 || interval > 9)
      throw std::invalid_argument("scip::scanCommand: interval must be 0..9, got " +
                                  std::to_string(interval));
    cmd += static_cast<char>('0' + interval);
    cmd += scip_detail::twoDigits(scans, "scans", 99);
  }
  return cmd + "\n";
}

std::vector<Reply> ReplyParser::feed(std::string_view bytes) {
  std::vector<Reply> out;
  for (const char c : bytes) {
    if (c == '\n') {
      if (discarding_) {
        discarding_ = false;
        line_.clear();
        continue;
      }
      if (!line_.empty() && line_.back() == '\r') line_.pop_back();
      if (line_.empty()) {
        if (!lines_.empty()) {
          out.push_back(scip_detail::buildReply(lines_));
          lines_.clear();
        }
        continue;
      }
      if (lines_.empty() && !scip_detail::looksLikeEcho(line_)) {
        skipped_ += line_.size() + 1;
      } else {
        lines_.push_back(std::move(line_));
      }
      line_.clear();
      continue;
    }
    if (discarding_) {
      ++skipped_;
      continue;
    }
    line_ += c;
    if (line_.size() > max_line_) {
      // No LF for too long: not SCIP (wrong baud rate, another device). Drop it and whatever
      // reply it was part of.
      skipped_ += line_.size();
      for (const auto& l : lines_) skipped_ += l.size() + 1;
      line_.clear();
      lines_.clear();
      discarding_ = true;
    }
  }
  return out;
}

std::uint64_t ReplyParser::bufferedBytes() const {
  std::uint64_t n = line_.size();
  for (const auto& l : lines_) n += l.size() + 1;
  return n;
}

void ReplyParser::reset() {
  line_.clear();
  lines_.clear();
  discarding_ = false;
}

std::string intensityCommand(int first, int last, int cluster, int interval, int scans) {
  std::string cmd = scanCommand(true, first, last, cluster, interval, scans, true);
  cmd[0] = 'M';
  cmd[1] = 'E';
  return cmd;
}

ScanDecode decodeScan(const Reply& reply, int chars, bool intensity) {
  ScanDecode d;
  if (chars != 2 && chars != 3) {
    d.error = "values must be 2 or 3 characters, got " + std::to_string(chars);
    return d;
  }
  if (!reply.error.empty()) {
    d.error = reply.error;
    return d;
  }
  if (reply.status != "00" && reply.status != "99") {
    d.error = "status " + reply.status + " (the device refused '" + reply.echo + "')";
    return d;
  }
  if (reply.payload.empty()) {
    d.error = "no scan data (status " + reply.status + ")";
    return d;
  }
  const auto ts = reply.payload[0].size() == 4 ? decode(reply.payload[0]) : std::nullopt;
  if (!ts) {
    d.error = "line 3: timestamp '" + reply.payload[0] + "' is not 4 encoded characters";
    return d;
  }
  std::string data;
  for (std::size_t k = 1; k < reply.payload.size(); ++k) data += reply.payload[k];
  if (data.size() % static_cast<std::size_t>(chars) != 0) {
    d.error = "scan data of " + std::to_string(data.size()) + " characters is not whole " +
              std::to_string(chars) + "-character values (a line lost?)";
    return d;
  }
  const std::size_t width = static_cast<std::size_t>(chars);
  if (intensity && data.size() % (2 * width) != 0) {
    d.error = "intensity scan data of " + std::to_string(data.size()) +
              " characters is not whole range-intensity pairs (a line lost?)";
    return d;
  }
  ScanReply s;
  s.timestamp_ms = *ts;
  s.ranges.reserve(data.size() / width / (intensity ? 2 : 1));
  if (intensity) s.intensities.reserve(s.ranges.capacity());
  for (std::size_t k = 0; k < data.size(); k += width) {
    const auto v = decode(std::string_view(data).substr(k, width));
    if (!v) {
      d.error = "value " + std::to_string(k / width) + " has a character outside the encoding";
      return d;
    }
    if (intensity && (k / width) % 2 == 1)
      s.intensities.push_back(*v);
    else
      s.ranges.push_back(*v);
  }
  d.scan = std::move(s);
  return d;
}

namespace scip_detail {

/// "KEY:VALUE;" lines of a PP/VV reply (the ';' ends the value; the payload line's checksum is
/// already gone).
std::optional<std::string> field(const Reply& reply, std::string_view key) {
  for (const auto& line : reply.payload) {
    if (line.size() <= key.size() || line.compare(0, key.size(), key) != 0 ||
        line[key.size()] != ':')
      continue;
    const auto end = line.find(';', key.size() + 1);
    if (end == std::string::npos) return std::nullopt;
    return line.substr(key.size() + 1, end - key.size() - 1);
  }
  return std::nullopt;
}

bool integerField(const Reply& reply, std::string_view key, int& out, std::string& error) {
  const auto v = field(reply, key);
  if (!v || v->empty() || v->size() > 9 ||
      !std::all_of(v->begin(), v->end(), [](char c) { return c >= '0' && c <= '9'; })) {
    error = "PP reply: field " + std::string(key) +
            (v ? " '" + *v + "' is not a number" : " is missing");
    return false;
  }
  out = std::stoi(*v);
  return true;
}

}  // namespace scip_detail

std::optional<SensorParameters> parseParameters(const Reply& reply, std::string& error) {
  if (!reply.error.empty()) {
    error = "PP reply: " + reply.error;
    return std::nullopt;
  }
  if (reply.status != "00") {
    error = "PP reply: status " + reply.status;
    return std::nullopt;
  }
  SensorParameters p;
  p.model = scip_detail::field(reply, "MODL").value_or("");
  using scip_detail::integerField;
  if (!integerField(reply, "DMIN", p.min_range_mm, error) ||
      !integerField(reply, "DMAX", p.max_range_mm, error) ||
      !integerField(reply, "ARES", p.steps_per_revolution, error) ||
      !integerField(reply, "AMIN", p.first_step, error) ||
      !integerField(reply, "AMAX", p.last_step, error) ||
      !integerField(reply, "AFRT", p.front_step, error) ||
      !integerField(reply, "SCAN", p.scan_rpm, error))
    return std::nullopt;
  if (p.steps_per_revolution <= 0 || p.first_step > p.last_step ||
      p.last_step >= p.steps_per_revolution || p.min_range_mm >= p.max_range_mm ||
      p.scan_rpm <= 0) {
    error = "PP reply: inconsistent geometry (ARES " + std::to_string(p.steps_per_revolution) +
            ", AMIN " + std::to_string(p.first_step) + ", AMAX " + std::to_string(p.last_step) +
            ", DMIN " + std::to_string(p.min_range_mm) + ", DMAX " +
            std::to_string(p.max_range_mm) + ", SCAN " + std::to_string(p.scan_rpm) + ")";
    return std::nullopt;
  }
  return p;
}

std::string encodeStatusReply(std::string_view echo, std::string_view status) {
  return std::string(echo) + '\n' + std::string(status) + checksum(status) + "\n\n";
}

std::string encodeParametersReply(const SensorParameters& p) {
  std::string out = std::string("PP\n00") + checksum("00") + '\n';
  const auto line = [&out](const std::string& key, const std::string& value) {
    const std::string l = key + ":" + value;
    out += l + ';' + checksum(l) + '\n';
  };
  line("MODL", p.model);
  line("DMIN", std::to_string(p.min_range_mm));
  line("DMAX", std::to_string(p.max_range_mm));
  line("ARES", std::to_string(p.steps_per_revolution));
  line("AMIN", std::to_string(p.first_step));
  line("AMAX", std::to_string(p.last_step));
  line("AFRT", std::to_string(p.front_step));
  line("SCAN", std::to_string(p.scan_rpm));
  return out + '\n';
}

std::string encodeScanReply(std::string_view echo, std::string_view status,
                            std::uint32_t timestamp_ms, const std::vector<std::uint32_t>& ranges,
                            int chars) {
  std::string out(echo);
  out += '\n';
  out += std::string(status) + checksum(status) + '\n';
  if (ranges.empty()) return out + '\n';  // an acknowledgement or a refusal: no data
  const std::string ts = encode(timestamp_ms & 0xFFFFFFu, 4);
  out += ts + checksum(ts) + '\n';
  std::string data;
  for (const auto r : ranges) data += encode(r, chars);
  for (std::size_t k = 0; k < data.size(); k += 64) {
    const std::string line = data.substr(k, 64);
    out += line + checksum(line) + '\n';
  }
  return out + '\n';
}

}  // namespace tessera::drivers::scip
