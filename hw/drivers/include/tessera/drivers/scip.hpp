// SCIP 2.0, the serial/TCP protocol of Hokuyo's URG and UTM laser scanners: the character
// encoding, line checksums, command strings and a byte-stream parser for replies
// (docs/architecture.md#device-drivers). Plain C++, no I/O and no runtime: the driver actor
// feeds it the bytes it reads, and the protocol emulator in the tests builds replies with it.
//
// Protocol summary (from the SCIP 2.0 specification):
//  * Numbers are sent 6 bits per character, most significant first, each as the byte
//    (bits + 0x30): 2 characters for 12-bit ranges (MS/GS), 3 for 18-bit ones (MD/GD), 4 for the
//    24-bit timestamp [ms]. E.g. 1234 = "CB", 5432 = "1Dh".
//  * Every reply line but the echo ends with a checksum character: the low 6 bits of the sum of
//    the line's other bytes, plus 0x30 (status "00" -> "00P"). Lines end with LF.
//  * A reply is the echo of the command line, a status line, then data lines, and ends with an
//    empty line. Scan data: a timestamp line, then the values in lines of at most 64 characters
//    (+ checksum); a value may be split across two lines.
//  * MD/GD status: "00" accepted (MD: the scans follow as separate replies), "99" a scan of an
//    MD stream; other codes are errors (e.g. "10" start step out of range).
// Ranges are in millimetres; values below 20 mm are the scanner's error codes.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::drivers::scip {

/// The checksum character of `line` (the bytes before it).
char checksum(std::string_view line);

/// `value` in `chars` (1..4) characters; throws std::invalid_argument when it does not fit.
std::string encode(std::uint32_t value, int chars);

/// The value of 1..4 encoded characters; nullopt for an empty or longer text or a byte outside
/// 0x30..0x6F.
std::optional<std::uint32_t> decode(std::string_view chars);

/// "MD" (continuous) or "GD" (one scan) command line, LF-terminated: steps first..last
/// (0..9999), `cluster` steps merged (0..99), for MD every `interval`-th scan skipped (0..9) and
/// `scans` scans (0 = until QT, 0..99). `three_chars` false selects MS/GS (2 characters).
std::string scanCommand(bool continuous, int first, int last, int cluster, int interval = 0,
                        int scans = 0, bool three_chars = true);

/// One complete reply: its echo line, status (2 characters, checksum checked), and payload
/// lines (checksum characters removed). `error` names what was wrong when the reply must not be
/// used (a checksum mismatch, a malformed line); the other fields then hold what was read.
struct Reply {
  std::string echo;
  std::string status;
  std::vector<std::string> payload;
  std::string error;
};

/// Splits a byte stream into replies. Bytes arrive in any chunks; a reply is returned once its
/// terminating empty line arrived. Bytes that cannot start a reply (not a printable command
/// echo) are skipped and counted, so garbage on the line resynchronises at the next reply. A
/// line longer than max_line bytes is garbage too (a stuck or wrong-baud device).
class ReplyParser {
 public:
  explicit ReplyParser(std::size_t max_line = 128) : max_line_(max_line) {}
  std::vector<Reply> feed(std::string_view bytes);
  std::uint64_t skippedBytes() const { return skipped_; }
  /// Bytes held for a reply that has not ended yet.
  std::uint64_t bufferedBytes() const;
  /// Drops a partial reply (e.g. after a reconnect).
  void reset();

 private:
  void finishLine();
  std::size_t max_line_;
  std::string line_;
  std::vector<std::string> lines_;
  bool discarding_ = false;
  std::uint64_t skipped_ = 0;
};

/// "ME" command line (continuous, 3-character ranges each followed by its 3-character
/// intensity), same arguments as scanCommand's MD.
std::string intensityCommand(int first, int last, int cluster, int interval = 0, int scans = 0);

/// A decoded scan reply (MD/GD/MS/GS/ME).
struct ScanReply {
  std::uint32_t timestamp_ms = 0;          ///< the sensor's 24-bit clock, wraps every 4.66 h
  std::vector<std::uint32_t> ranges;       ///< [mm] per (clustered) step, first..last
  std::vector<std::uint32_t> intensities;  ///< ME only: one per range, the sensor's units
};

/// Decodes the payload of a scan reply with `chars` (2 or 3) characters per value; with
/// `intensity` (ME), values alternate range and intensity. Errors (the reply's own, a missing
/// timestamp, a payload that is not whole values, a bad character) come back in `error`, naming
/// the line.
struct ScanDecode {
  std::optional<ScanReply> scan;
  std::string error;
};
ScanDecode decodeScan(const Reply& reply, int chars, bool intensity = false);

/// The "PP" reply: the sensor's geometry and range limits. Step s looks at
/// (s - front_step) * 2 pi / steps_per_revolution [rad], counter-clockwise, 0 ahead.
struct SensorParameters {
  std::string model;             ///< MODL, e.g. "URG-04LX(Hokuyo Automatic Co.,Ltd.)"
  int min_range_mm = 0;          ///< DMIN
  int max_range_mm = 0;          ///< DMAX
  int steps_per_revolution = 0;  ///< ARES
  int first_step = 0;            ///< AMIN
  int last_step = 0;             ///< AMAX
  int front_step = 0;            ///< AFRT
  int scan_rpm = 0;              ///< SCAN: motor speed [1/min], one scan per revolution
};
/// nullopt with the reason in `error` when the reply is not a valid PP answer (a missing or
/// non-numeric field, an inconsistent geometry).
std::optional<SensorParameters> parseParameters(const Reply& reply, std::string& error);

/// The PP reply a device sends (the emulator's side).
std::string encodeParametersReply(const SensorParameters& p);

/// A reply without data lines: echo and status (checksum added).
std::string encodeStatusReply(std::string_view echo, std::string_view status);

/// The lines of a scan reply as a device sends them (the emulator's side): echo, status with
/// checksum, timestamp, values in lines of 64 characters, the empty line. Without ranges, only
/// echo and status (an MD acknowledgement or a refusal).
std::string encodeScanReply(std::string_view echo, std::string_view status,
                            std::uint32_t timestamp_ms, const std::vector<std::uint32_t>& ranges,
                            int chars);

}  // namespace tessera::drivers::scip
