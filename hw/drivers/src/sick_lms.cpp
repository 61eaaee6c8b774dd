// The SICK LMS2xx telegram protocol: see sick_lms.hpp.
#include <tessera/drivers/sick_lms.hpp>

namespace tessera::drivers::sick {

std::uint16_t crc16(std::string_view bytes) {
  // The telegram listing's algorithm: shift the CRC, fold in the generator when its top bit
  // falls out, and XOR in the last two bytes (newest low).
  std::uint16_t crc = 0;
  std::uint8_t previous = 0;
  for (const char c : bytes) {
    const auto byte = static_cast<std::uint8_t>(c);
    if (crc & 0x8000u)
      crc = static_cast<std::uint16_t>(((crc & 0x7FFFu) << 1) ^ 0x8005u);
    else
      crc = static_cast<std::uint16_t>(crc << 1);
    crc ^= static_cast<std::uint16_t>(byte | (previous << 8));
    previous = byte;
  }
  return crc;
}

namespace {

void putWord(std::string& out, std::uint16_t v) {
  out += static_cast<char>(v & 0xFF);
  out += static_cast<char>(v >> 8);
}

std::uint16_t word(std::string_view s, std::size_t at) {
  return static_cast<std::uint16_t>(static_cast<std::uint8_t>(s[at]) |
                                    (static_cast<std::uint8_t>(s[at + 1]) << 8));
}

}  // namespace

std::string frame(std::uint8_t address, std::string_view payload) {
  std::string out;
  out += static_cast<char>(kStx);
  out += static_cast<char>(address);
  putWord(out, static_cast<std::uint16_t>(payload.size()));
  out += payload;
  putWord(out, crc16(out));
  return out;
}

std::vector<TelegramParser::Item> TelegramParser::feed(std::string_view bytes) {
  buffer_ += bytes;
  std::vector<Item> out;
  std::size_t at = 0;
  while (at < buffer_.size()) {
    const auto first = static_cast<std::uint8_t>(buffer_[at]);
    if (first == kAck || first == kNak) {
      Item item;
      item.kind = first == kAck ? Item::Kind::kAck : Item::Kind::kNak;
      out.push_back(std::move(item));
      ++at;
      continue;
    }
    if (first != kStx) {
      ++skipped_;
      ++at;
      continue;
    }
    if (buffer_.size() - at < 4) break;  // the header is not all here yet
    const std::size_t length = word(buffer_, at + 2);
    const auto address = static_cast<std::uint8_t>(buffer_[at + 1]);
    // Not a telegram's start (an STX in noise): addresses are 0x00-0x0F to a sensor and
    // 0x80-0x8F from one, and no telegram is empty or longer than the longest scan.
    if ((address & 0x70u) != 0 || length == 0 || length > max_length_) {
      ++skipped_;
      ++at;
      continue;
    }
    if (buffer_.size() - at < 4 + length + 2) break;
    const std::string_view whole(buffer_.data() + at, 4 + length);
    if (crc16(whole) != word(buffer_, at + 4 + length)) {
      ++bad_crc_;
      ++skipped_;
      ++at;  // resynchronise: the next STX may be the real start
      continue;
    }
    Item item;
    item.telegram.address = static_cast<std::uint8_t>(buffer_[at + 1]);
    item.telegram.command = static_cast<std::uint8_t>(buffer_[at + 4]);
    item.telegram.data = std::string(buffer_.data() + at + 5, length - 1);
    out.push_back(std::move(item));
    at += 4 + length + 2;
  }
  buffer_.erase(0, at);
  return out;
}

std::string modeCommand(std::uint8_t mode, std::string_view password) {
  std::string out("\x20", 1);
  out += static_cast<char>(mode);
  out += password;
  return out;
}

std::optional<std::uint8_t> baudMode(int baud) {
  switch (baud) {
    case 9600:
      return 0x42;
    case 19200:
      return 0x41;
    case 38400:
      return 0x40;
    case 500000:
      return 0x48;
    default:
      return std::nullopt;
  }
}

std::string variantCommand(int angle_deg, int resolution_centideg) {
  std::string out("\x3B", 1);
  putWord(out, static_cast<std::uint16_t>(angle_deg));
  putWord(out, static_cast<std::uint16_t>(resolution_centideg));
  return out;
}

std::string configCommand(const std::string& config) {
  return std::string("\x77", 1) + config;
}

std::optional<Scan> decodeScan(const Telegram& t, std::string& error) {
  if (t.command != 0xB0) {
    error = "not a scan telegram (command 0x" + std::to_string(t.command) + ")";
    return std::nullopt;
  }
  if (t.data.size() < 3) {
    error = "scan telegram of " + std::to_string(t.data.size()) + " bytes, too short";
    return std::nullopt;
  }
  const std::uint16_t head = word(t.data, 0);
  const std::size_t count = head & 0x3FFu;
  const unsigned units = (head >> 14) & 0x3u;
  if (units > 1) {
    error = "scan telegram with unknown units " + std::to_string(units);
    return std::nullopt;
  }
  if (t.data.size() != 2 + 2 * count + 1) {
    error = "scan telegram says " + std::to_string(count) + " values but holds " +
            std::to_string(t.data.size()) + " bytes (expected " +
            std::to_string(2 + 2 * count + 1) + ")";
    return std::nullopt;
  }
  Scan s;
  s.millimetres = units == 1;
  s.values.resize(count);
  for (std::size_t k = 0; k < count; ++k) s.values[k] = word(t.data, 2 + 2 * k) & 0x1FFFu;
  s.status = static_cast<std::uint8_t>(t.data.back());
  return s;
}

std::string encodeScan(const Scan& s) {
  std::string out("\xB0", 1);
  putWord(out,
          static_cast<std::uint16_t>((s.values.size() & 0x3FFu) | (s.millimetres ? 0x4000u : 0u)));
  for (const auto v : s.values) putWord(out, static_cast<std::uint16_t>(v & 0x1FFFu));
  out += static_cast<char>(s.status);
  return out;
}

}  // namespace tessera::drivers::sick
