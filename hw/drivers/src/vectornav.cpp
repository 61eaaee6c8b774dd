// The VN-100 ASCII codec: see vectornav.hpp.
#include <tessera/drivers/vectornav.hpp>

#include <charconv>
#include <cmath>
#include <cstdio>

namespace tessera::drivers::vn {

namespace vn_detail {

constexpr char kHex[] = "0123456789ABCDEF";

int hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

std::string twoDigits(int reg) {
  std::string s = std::to_string(reg);
  return s.size() < 2 ? "0" + s : s;
}

/// Up to 24 bytes of `s` for an error message, non-text bytes as \xNN.
std::string shown(std::string_view s) {
  std::string out;
  for (std::size_t k = 0; k < s.size() && k < 24; ++k) {
    const auto b = static_cast<unsigned char>(s[k]);
    if (b >= 0x20 && b < 0x7F) {
      out += static_cast<char>(b);
    } else {
      out.append("\\x");
      out += kHex[b >> 4];
      out += kHex[b & 0xF];
    }
  }
  if (s.size() > 24) out.append("...");
  return out;
}

enum class Number { kOk, kNotFinite, kBad };

/// A signed fixed-point decimal (+000.123, -9, 12.5); "nan" and "inf" in any case are kNotFinite.
Number parseNumber(std::string_view s, double& v) {
  std::string_view d = s;
  const bool negative = !d.empty() && d[0] == '-';
  if (!d.empty() && (d[0] == '+' || d[0] == '-')) d.remove_prefix(1);
  if (d.size() >= 3) {
    std::string head;
    for (std::size_t k = 0; k < 3; ++k)
      head += static_cast<char>(d[k] >= 'A' && d[k] <= 'Z' ? d[k] - 'A' + 'a' : d[k]);
    if (head == "nan" || head == "inf") return Number::kNotFinite;
  }
  std::size_t k = 0, int_digits = 0, frac_digits = 0;
  while (k < d.size() && d[k] >= '0' && d[k] <= '9') ++k, ++int_digits;
  if (k < d.size() && d[k] == '.') {
    ++k;
    while (k < d.size() && d[k] >= '0' && d[k] <= '9') ++k, ++frac_digits;
    if (frac_digits == 0) return Number::kBad;
  }
  if (int_digits == 0 || k != d.size()) return Number::kBad;
  const auto [end, ec] = std::from_chars(d.data(), d.data() + d.size(), v);
  if (ec != std::errc() || end != d.data() + d.size()) return Number::kBad;
  if (negative) v = -v;
  return std::isfinite(v) ? Number::kOk : Number::kNotFinite;
}

std::string number(double v, int width, int precision) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%+0*.*f", width, precision, v);
  return buf;
}

struct Layout {
  const char* header;
  int type;
  std::vector<const char*> names;
};

const std::vector<Layout>& layouts() {
  static const std::vector<Layout> all = {
      {"VNYMR",
       kTypeYmr,
       {"yaw", "pitch", "roll", "mag x", "mag y", "mag z", "accel x", "accel y", "accel z",
        "gyro x", "gyro y", "gyro z"}},
      {"VNIMU",
       kTypeImu,
       {"mag x", "mag y", "mag z", "accel x", "accel y", "accel z", "gyro x", "gyro y", "gyro z",
        "temperature", "pressure"}},
      {"VNYPR", kTypeYpr, {"yaw", "pitch", "roll"}},
  };
  return all;
}

}  // namespace vn_detail

const std::vector<int>& outputRates() {
  static const std::vector<int> rates{1, 2, 4, 5, 10, 20, 25, 40, 50, 100, 200};
  return rates;
}

const std::vector<int>& baudRates() {
  static const std::vector<int> rates{9600,   19200,  38400,  57600, 115200,
                                      128000, 230400, 460800, 921600};
  return rates;
}

std::string errorName(int code) {
  switch (code) {
    case 1:
      return "hard fault";
    case 2:
      return "serial buffer overflow";
    case 3:
      return "invalid checksum";
    case 4:
      return "invalid command";
    case 5:
      return "not enough parameters";
    case 6:
      return "too many parameters";
    case 7:
      return "invalid parameter";
    case 8:
      return "invalid register";
    case 9:
      return "unauthorized access";
    case 10:
      return "watchdog reset";
    case 11:
      return "output buffer overflow";
    case 12:
      return "insufficient baud rate";
    case 255:
      return "error buffer overflow";
    default:
      return "unknown error";
  }
}

std::uint8_t checksum(std::string_view body) {
  std::uint8_t x = 0;
  for (const char c : body) x ^= static_cast<std::uint8_t>(c);
  return x;
}

std::string frame(std::string_view body) {
  const std::uint8_t x = checksum(body);
  std::string out = "$";
  out.append(body);
  out += '*';
  out += vn_detail::kHex[x >> 4];
  out += vn_detail::kHex[x & 0xF];
  out.append("\r\n");
  return out;
}

std::string readRegister(int reg) {
  std::string body = "VNRRG,";
  body.append(vn_detail::twoDigits(reg));
  return frame(body);
}

std::string writeRegister(int reg, std::string_view values) {
  std::string body = "VNWRG,";
  body.append(vn_detail::twoDigits(reg));
  body += ',';
  body.append(values);
  return frame(body);
}

const char* faultName(Fault f) {
  switch (f) {
    case Fault::kTruncated:
      return "truncated";
    case Fault::kMalformed:
      return "malformed";
    case Fault::kChecksum:
      return "checksum";
    case Fault::kNotFinite:
      return "not finite";
    default:
      return "none";
  }
}

std::optional<Message> parseLine(std::string_view line, Problem& problem, bool unchecked_ok) {
  using vn_detail::shown;
  const auto fail = [&problem](Fault f, std::string what) -> std::optional<Message> {
    problem = {f, std::move(what)};
    return std::nullopt;
  };
  if (line.empty() || line == "$") return fail(Fault::kMalformed, "empty line");
  if (line[0] != '$')
    return fail(Fault::kMalformed, "'" + shown(line) + "' does not start with '$'");
  const std::size_t star = line.rfind('*');
  if (star == std::string_view::npos)
    return fail(Fault::kTruncated, "'" + shown(line) + "' ends after " +
                                       std::to_string(line.size()) + " bytes without '*' checksum");
  const std::string_view digits = line.substr(star + 1);
  if (digits.size() < 2)
    return fail(Fault::kTruncated, "checksum cut short: '*" + shown(digits) + "'");
  const bool unchecked = unchecked_ok && digits == "XX";
  const int hi = vn_detail::hexValue(digits[0]), lo = vn_detail::hexValue(digits[1]);
  if (!unchecked && (digits.size() > 2 || hi < 0 || lo < 0))
    return fail(Fault::kMalformed, "checksum '" + shown(digits) + "' is not two hex digits");
  const std::string_view body = line.substr(1, star - 1);
  if (!unchecked) {
    const int sent = hi * 16 + lo, computed = checksum(body);
    if (sent != computed) {
      std::string what = "checksum ";
      what.append(std::string(digits)).append(", computed ");
      what += vn_detail::kHex[computed >> 4];
      what += vn_detail::kHex[computed & 0xF];
      what.append(" ('").append(shown(line)).append("')");
      return fail(Fault::kChecksum, what);
    }
  }
  if (body.empty()) return fail(Fault::kMalformed, "empty message ('" + shown(line) + "')");
  for (std::size_t k = 0; k < body.size(); ++k) {
    const auto b = static_cast<unsigned char>(body[k]);
    if (b < 0x20 || b >= 0x7F)
      return fail(Fault::kMalformed,
                  "byte " + std::to_string(k + 1) + " is not text ('" + shown(line) + "')");
  }
  Message m;
  std::size_t at = 0;
  while (true) {
    const std::size_t comma = body.find(',', at);
    const std::string_view field =
        body.substr(at, comma == std::string_view::npos ? std::string_view::npos : comma - at);
    if (m.header.empty() && at == 0)
      m.header = std::string(field);
    else
      m.fields.emplace_back(field);
    if (comma == std::string_view::npos) break;
    at = comma + 1;
  }
  const auto& h = m.header;
  bool letters = h.size() == 5 && h.compare(0, 2, "VN") == 0;
  for (const char c : h) letters = letters && c >= 'A' && c <= 'Z';
  if (!letters) return fail(Fault::kMalformed, "'" + shown(h) + "' is not a VN-100 message");
  return m;
}

std::optional<Sample> decodeSample(const Message& m, Problem& problem) {
  namespace d = vn_detail;
  const d::Layout* layout = nullptr;
  for (const auto& l : d::layouts())
    if (m.header == l.header) layout = &l;
  if (!layout) {
    problem = {Fault::kMalformed, m.header + " is not an output this driver reads"};
    return std::nullopt;
  }
  const std::size_t n = layout->names.size();
  if (m.fields.size() != n) {
    problem = {m.fields.size() < n ? Fault::kTruncated : Fault::kMalformed,
               m.header + " with " + std::to_string(m.fields.size()) + " values, not " +
                   std::to_string(n)};
    return std::nullopt;
  }
  std::vector<double> v(n);
  for (std::size_t k = 0; k < n; ++k) {
    const std::string what = m.header + " value " + std::to_string(k + 1) + " (" +
                             layout->names[k] + ") '" + d::shown(m.fields[k]) + "'";
    switch (d::parseNumber(m.fields[k], v[k])) {
      case d::Number::kOk:
        break;
      case d::Number::kNotFinite:
        problem = {Fault::kNotFinite, what + " is not finite"};
        return std::nullopt;
      case d::Number::kBad:
        problem = {Fault::kMalformed, m.fields[k].empty()
                                          ? m.header + " value " + std::to_string(k + 1) + " (" +
                                                layout->names[k] + ") is empty"
                                          : what + " is not a number"};
        return std::nullopt;
    }
  }
  Sample s;
  s.type = layout->type;
  std::size_t at = 0;
  const auto take3 = [&v, &at](std::array<double, 3>& a) {
    for (auto& x : a) x = v[at++];
  };
  if (s.type == kTypeYmr || s.type == kTypeYpr) {
    s.yaw_deg = v[0];
    s.pitch_deg = v[1];
    s.roll_deg = v[2];
    at = 3;
  }
  if (s.type == kTypeYpr) return s;
  take3(s.mag_gauss);
  take3(s.accel);
  take3(s.gyro);
  if (s.type == kTypeImu) {
    s.temperature_c = v[at];
    s.pressure_kpa = v[at + 1];
  }
  return s;
}

std::string encodeSample(const Sample& s) {
  using vn_detail::number;
  std::string out;
  const auto put = [&out](const std::string& text) {
    out += ',';
    out.append(text);
  };
  const auto put3 = [&put](const std::array<double, 3>& a, int width, int precision) {
    for (const double x : a) put(number(x, width, precision));
  };
  if (s.type == kTypeYmr || s.type == kTypeYpr) {
    out = s.type == kTypeYmr ? "VNYMR" : "VNYPR";
    put(number(s.yaw_deg, 8, 3));
    put(number(s.pitch_deg, 8, 3));
    put(number(s.roll_deg, 8, 3));
    if (s.type == kTypeYpr) return out;
  } else {
    out = "VNIMU";
  }
  put3(s.mag_gauss, 8, 4);
  put3(s.accel, 8, 4);
  put3(s.gyro, 9, 6);
  if (s.type == kTypeImu) {
    put(number(s.temperature_c, 5, 1));
    put(number(s.pressure_kpa, 8, 3));
  }
  return out;
}

std::size_t lineBytes(int type) {
  Sample s;
  s.type = type;
  s.yaw_deg = s.roll_deg = -179.999;
  s.pitch_deg = -89.999;
  s.mag_gauss = {-1.5, -1.5, -1.5};
  s.accel = {-9.81, -9.81, -9.81};
  s.gyro = {-1.5, -1.5, -1.5};
  s.temperature_c = 25.0;
  s.pressure_kpa = 101.325;
  return frame(encodeSample(s)).size();
}

std::array<double, 3> fromRep103(const std::array<double, 3>& v) {
  return {v[0], -v[1], -v[2]};
}

Rep103 toRep103(const Sample& s) {
  // The same flip both ways: a rotation by pi about x.
  return {fromRep103(s.gyro), fromRep103(s.accel)};
}

std::vector<LineSplitter::Line> LineSplitter::feed(std::string_view bytes) {
  std::vector<Line> out;
  // Where the current line's '$' is, relative to this chunk (negative: an earlier chunk).
  auto start = -static_cast<std::ptrdiff_t>(line_.size());
  const auto tail = [&bytes, &start] {
    return static_cast<std::size_t>(static_cast<std::ptrdiff_t>(bytes.size()) - start);
  };
  for (std::size_t k = 0; k < bytes.size(); ++k) {
    const char c = bytes[k];
    if (c == '$') {
      if (in_line_) out.push_back({std::move(line_), tail(), true});
      line_.assign(1, '$');
      in_line_ = true;
      start = static_cast<std::ptrdiff_t>(k);
      continue;
    }
    if (!in_line_) {
      ++skipped_;
      continue;
    }
    if (c == '\n') {
      if (!line_.empty() && line_.back() == '\r') line_.pop_back();
      out.push_back({std::move(line_), tail(), false});
      line_.clear();
      in_line_ = false;
      continue;
    }
    line_ += c;
    if (line_.size() > max_length_) {  // never a VN-100 line: drop it and look for the next '$'
      out.push_back({std::move(line_), tail(), true});
      line_.clear();
      in_line_ = false;
    }
  }
  return out;
}

}  // namespace tessera::drivers::vn
