// The iRobot Open Interface codec: see create_oi.hpp.
#include <tessera/drivers/create_oi.hpp>

#include <algorithm>
#include <cmath>

namespace tessera::drivers::oi {

namespace oi_detail {

void put16(std::string& out, int v) {
  const auto u = static_cast<std::uint16_t>(static_cast<std::int16_t>(v));
  out += static_cast<char>(u >> 8);
  out += static_cast<char>(u & 0xFF);
}

std::uint16_t get16(std::string_view s, std::size_t at) {
  return static_cast<std::uint16_t>((static_cast<std::uint8_t>(s[at]) << 8) |
                                    static_cast<std::uint8_t>(s[at + 1]));
}

}  // namespace oi_detail

const std::vector<std::uint8_t>& streamedPackets() {
  static const std::vector<std::uint8_t> ids{7, 9, 10, 11, 12, 21, 22, 23, 25, 26, 43, 44};
  return ids;
}

int packetSize(std::uint8_t id) {
  switch (id) {
    case 7:
    case 9:
    case 10:
    case 11:
    case 12:
    case 21:
      return 1;
    case 22:
    case 23:
    case 25:
    case 26:
    case 43:
    case 44:
      return 2;
    default:
      return 0;
  }
}

std::string driveDirect(double right_mm_s, double left_mm_s) {
  const auto clamp = [](double v) {
    return std::isfinite(v) ? static_cast<int>(std::lround(std::clamp(v, -500.0, 500.0))) : 0;
  };
  std::string out(1, static_cast<char>(kDriveDirect));
  oi_detail::put16(out, clamp(right_mm_s));
  oi_detail::put16(out, clamp(left_mm_s));
  return out;
}

std::string streamCommand(const std::vector<std::uint8_t>& ids) {
  std::string out(1, static_cast<char>(kStream));
  out += static_cast<char>(ids.size());
  for (const auto id : ids) out += static_cast<char>(id);
  return out;
}

std::string encodeFrame(const SensorFrame& f) {
  using oi_detail::put16;
  std::string body;
  for (const auto id : streamedPackets()) {
    body += static_cast<char>(id);
    switch (id) {
      case 7:
        body += static_cast<char>((f.bump_right ? 1 : 0) | (f.bump_left ? 2 : 0) |
                                  (f.wheel_drop_right ? 4 : 0) | (f.wheel_drop_left ? 8 : 0));
        break;
      case 9:
        body += static_cast<char>(f.cliff_left);
        break;
      case 10:
        body += static_cast<char>(f.cliff_front_left);
        break;
      case 11:
        body += static_cast<char>(f.cliff_front_right);
        break;
      case 12:
        body += static_cast<char>(f.cliff_right);
        break;
      case 21:
        body += static_cast<char>(f.charging_state);
        break;
      case 22:
        put16(body, f.voltage_mv);
        break;
      case 23:
        put16(body, f.current_ma);
        break;
      case 25:
        put16(body, f.charge_mah);
        break;
      case 26:
        put16(body, f.capacity_mah);
        break;
      case 43:
        put16(body, f.left_counts);
        break;
      case 44:
        put16(body, f.right_counts);
        break;
      default:
        break;
    }
  }
  std::string out(1, static_cast<char>(kStreamHeader));
  out += static_cast<char>(body.size());
  out += body;
  unsigned sum = 0;
  for (const char c : out) sum += static_cast<std::uint8_t>(c);
  out += static_cast<char>((256 - (sum & 0xFF)) & 0xFF);
  return out;
}

namespace oi_detail {

/// The packets of a frame's body; false when one is unknown or cut.
bool parseBody(std::string_view body, SensorFrame& f) {
  std::size_t at = 0;
  while (at < body.size()) {
    const auto id = static_cast<std::uint8_t>(body[at++]);
    const int size = packetSize(id);
    if (size == 0 || at + static_cast<std::size_t>(size) > body.size()) return false;
    const auto b = static_cast<std::uint8_t>(body[at]);
    switch (id) {
      case 7:
        if (b & 0xF0) return false;  // reserved bits: not a real packet 7
        f.bump_right = b & 1;
        f.bump_left = b & 2;
        f.wheel_drop_right = b & 4;
        f.wheel_drop_left = b & 8;
        break;
      case 9:
      case 10:
      case 11:
      case 12:
        if (b > 1) return false;
        (id == 9    ? f.cliff_left
         : id == 10 ? f.cliff_front_left
         : id == 11 ? f.cliff_front_right
                    : f.cliff_right) = b == 1;
        break;
      case 21:
        f.charging_state = b;
        break;
      case 22:
        f.voltage_mv = get16(body, at);
        break;
      case 23:
        f.current_ma = static_cast<std::int16_t>(get16(body, at));
        break;
      case 25:
        f.charge_mah = get16(body, at);
        break;
      case 26:
        f.capacity_mah = get16(body, at);
        break;
      case 43:
        f.left_counts = get16(body, at);
        break;
      case 44:
        f.right_counts = get16(body, at);
        break;
      default:
        return false;
    }
    at += static_cast<std::size_t>(size);
  }
  return true;
}

}  // namespace oi_detail

std::vector<SensorFrame> StreamParser::feed(std::string_view bytes) {
  buffer_ += bytes;
  std::vector<SensorFrame> out;
  std::size_t at = 0;
  while (at < buffer_.size()) {
    if (static_cast<std::uint8_t>(buffer_[at]) != kStreamHeader) {
      ++skipped_;
      ++at;
      continue;
    }
    if (buffer_.size() - at < 3) break;
    const std::size_t n = static_cast<std::uint8_t>(buffer_[at + 1]);
    // Not a frame's start: another body size than asked for, or no packet id after it.
    if ((body_bytes_ > 0 && n != body_bytes_) || n == 0 ||
        packetSize(static_cast<std::uint8_t>(buffer_[at + 2])) == 0) {
      ++skipped_;
      ++at;
      continue;
    }
    if (buffer_.size() - at < n + 3) break;
    unsigned sum = 0;
    for (std::size_t k = at; k < at + n + 3; ++k) sum += static_cast<std::uint8_t>(buffer_[k]);
    SensorFrame f;
    if ((sum & 0xFF) != 0 ||
        !oi_detail::parseBody(std::string_view(buffer_).substr(at + 2, n), f)) {
      ++bad_;
      ++skipped_;
      ++at;  // a 19 inside data, or a damaged frame: look again from the next byte
      continue;
    }
    out.push_back(f);
    at += n + 3;
  }
  buffer_.erase(0, at);
  if (buffer_.size() > 4096) {  // never a frame: do not hold on to it
    skipped_ += buffer_.size();
    buffer_.clear();
  }
  return out;
}

std::size_t frameBodyBytes(const std::vector<std::uint8_t>& ids) {
  std::size_t n = 0;
  for (const auto id : ids) n += 1 + static_cast<std::size_t>(packetSize(id));
  return n;
}

std::int64_t EncoderUnwrap::operator()(std::uint16_t counts) {
  if (last_) total_ += static_cast<std::int16_t>(static_cast<std::uint16_t>(counts - *last_));
  last_ = counts;
  return total_;
}

}  // namespace tessera::drivers::oi
