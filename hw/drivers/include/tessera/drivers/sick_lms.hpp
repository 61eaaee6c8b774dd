// The SICK LMS200/291 telegram protocol (RS-232/RS-422), from the LMS2xx telegram listing:
// framing, CRC, the commands a driver sends, and the scans it receives
// (docs/architecture.md#device-drivers). Plain C++, no I/O.
//
// A telegram is STX (0x02), address (0x00 to the sensor, 0x80 from it), length (uint16, little
// endian: the bytes from the command to the status, inclusive), command, data, and a CRC16
// (little endian) over everything before it. Replies have command | 0x80 and end with a status
// byte. The sensor acknowledges each telegram it receives with ACK (0x06) or, when its CRC
// fails, NAK (0x15), before any reply.
//
// Commands used: 0x20 operating mode (0x24 stream every scan, 0x25 stop, 0x40/0x41/0x42/0x48
// = 38400/19200/9600/500000 baud, 0x00 + "SICK_LMS" = installation mode), 0x3B variant (scan
// angle 100/180 deg, resolution 0.25/0.5/1 deg), 0x74 read and 0x77 write the configuration
// (byte 10: units, 0 cm / 1 mm). Scans come as 0xB0: a count word (bits 0-9 the number of
// values, bits 14-15 the units: 0 cm, 1 mm), the values (bits 0-12 the range, 13-15 flags),
// the status byte. Range values from 8183 up are the sensor's codes for no echo or overflow.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::drivers::sick {

constexpr std::uint8_t kStx = 0x02, kAck = 0x06, kNak = 0x15;
constexpr std::uint8_t kToSensor = 0x00, kFromSensor = 0x80;
constexpr std::size_t kUnitsByte = 10;      ///< in the 0x74/0x77 configuration block
constexpr std::uint16_t kFirstCode = 8183;  ///< range values from here on are codes, not ranges

/// The LMS's CRC16 (generator 0x8005, over byte pairs as the telegram listing defines it).
std::uint16_t crc16(std::string_view bytes);

/// A complete telegram: STX, address, length, `payload` (command and data), CRC.
std::string frame(std::uint8_t address, std::string_view payload);

struct Telegram {
  std::uint8_t address = 0;
  std::uint8_t command = 0;
  std::string data;  ///< after the command; a reply's last byte is its status
};

/// Splits a byte stream into telegrams, ACKs and NAKs. Bytes in any chunks; garbage and
/// telegrams whose CRC fails are skipped and counted, and the search resumes at the next STX.
/// An STX is taken for a telegram's start only with a plausible address (0x00-0x0F, 0x80-0x8F)
/// and length (1..max_length); a false start that passes both costs the wait for its length in
/// bytes, then its CRC fails and the bytes it held are searched again.
class TelegramParser {
 public:
  struct Item {
    enum class Kind { kTelegram, kAck, kNak } kind = Kind::kTelegram;
    Telegram telegram;
  };
  explicit TelegramParser(std::size_t max_length = 1024) : max_length_(max_length) {}
  std::vector<Item> feed(std::string_view bytes);
  std::uint64_t skippedBytes() const { return skipped_; }
  std::uint64_t badCrcs() const { return bad_crc_; }
  std::uint64_t bufferedBytes() const { return buffer_.size(); }

 private:
  std::size_t max_length_;
  std::string buffer_;
  std::uint64_t skipped_ = 0, bad_crc_ = 0;
};

// Commands (payloads for frame(kToSensor, ...)).
std::string modeCommand(std::uint8_t mode, std::string_view password = "");
/// 0x20's mode byte for a baud rate; nullopt for a rate the LMS does not have.
std::optional<std::uint8_t> baudMode(int baud);
std::string variantCommand(int angle_deg, int resolution_centideg);
inline std::string configRequest() {
  return std::string(1, '\x74');
}
std::string configCommand(const std::string& config);

/// A decoded 0xB0 scan.
struct Scan {
  bool millimetres = false;           ///< units: mm (true) or cm
  std::vector<std::uint16_t> values;  ///< 13-bit ranges in those units (codes from kFirstCode)
  std::uint8_t status = 0;
};
/// nullopt with the reason in `error` when the telegram is not a whole 0xB0 scan.
std::optional<Scan> decodeScan(const Telegram& t, std::string& error);
/// A 0xB0 telegram's payload (the emulator's side).
std::string encodeScan(const Scan& s);

}  // namespace tessera::drivers::sick
