// The VectorNav VN-100 ASCII protocol, from its user manual: framing and checksum, the register
// commands a driver sends, and the async output lines it reads
// (docs/architecture.md#device-drivers). Plain C++, no I/O.
//
// A message is '$', a body, '*', two hex digits and CR LF; the digits are the XOR of the body's
// bytes (between '$' and '*'). Host commands: VNRRG,<reg> reads a register, VNWRG,<reg>,<values>
// writes one; the reply echoes the command with the register's values, or is VNERR,<code>.
// Registers used: 1 model, 3 serial number, 5 baud rate (the reply goes out at the old rate, then
// the device switches), 6 async output type (0 off, 1 VNYPR, 8 VNYMR, 19 VNIMU), 7 async output
// rate [Hz].
//
// Async outputs, numbers as signed fixed-point decimals (+000.123):
//   VNYMR  yaw, pitch, roll [deg], magnetic x y z [gauss], acceleration x y z [m/s^2],
//          angular rate x y z [rad/s]
//   VNIMU  magnetic x y z, acceleration x y z, angular rate x y z, temperature [C], pressure [kPa]
//
// Frames: the VN-100 body frame is x forward, y right, z down. toRep103() gives x forward, y left,
// z up (REP-103, what msg::ImuSample carries) by negating y and z of the angular rate and of the
// acceleration: a counter-clockwise turn seen from above is a negative VN-100 z rate and a
// positive REP-103 one; level and at rest the VN-100 reads acceleration z = -g, REP-103 +g.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace tessera::drivers::vn {

constexpr int kModelRegister = 1, kSerialRegister = 3, kBaudRegister = 5, kTypeRegister = 6,
              kRateRegister = 7;
constexpr int kTypeOff = 0, kTypeYpr = 1, kTypeYmr = 8, kTypeImu = 19;

/// The async output a driver asks for (its `output` option).
enum class Output { kImu, kYmr };
constexpr std::array<std::pair<const char*, Output>, 2> optionNames(Output) {
  return {{{"imu", Output::kImu}, {"ymr", Output::kYmr}}};
}
constexpr int asyncType(Output o) {
  return o == Output::kImu ? kTypeImu : kTypeYmr;
}

/// The rates [Hz] register 7 takes, and the baud rates register 5 takes.
const std::vector<int>& outputRates();
const std::vector<int>& baudRates();
/// What a VNERR code means ("invalid checksum"); "unknown error" for a code the manual lacks.
std::string errorName(int code);

std::uint8_t checksum(std::string_view body);
/// '$' + body + '*' + checksum + CR LF.
std::string frame(std::string_view body);
std::string readRegister(int reg);
std::string writeRegister(int reg, std::string_view values);

/// Why a line was dropped. Every fault drops the whole line.
enum class Fault { kNone, kTruncated, kMalformed, kChecksum, kNotFinite };
const char* faultName(Fault f);
struct Problem {
  Fault fault = Fault::kNone;
  std::string what;
};

/// A line whose checksum and framing are good: its header ("VNYMR") and the fields after it.
struct Message {
  std::string header;
  std::vector<std::string> fields;
};
/// Checks a line ('$' up to, not including, CR LF) and splits it. `unchecked_ok`: "*XX" stands
/// for no checksum, as the device accepts from a host.
std::optional<Message> parseLine(std::string_view line, Problem& problem,
                                 bool unchecked_ok = false);

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// A VNYMR or VNIMU sample in the VN-100 body frame (x forward, y right, z down). What its
/// output does not carry is NaN.
struct Sample {
  int type = kTypeImu;
  double yaw_deg = kNaN, pitch_deg = kNaN, roll_deg = kNaN;  ///< VNYMR
  std::array<double, 3> mag_gauss{kNaN, kNaN, kNaN};
  std::array<double, 3> accel{kNaN, kNaN, kNaN};     ///< [m/s^2] specific force
  std::array<double, 3> gyro{kNaN, kNaN, kNaN};      ///< [rad/s]
  double temperature_c = kNaN, pressure_kpa = kNaN;  ///< VNIMU
};
/// A VNYMR or VNIMU message's values; nullopt with the problem (value count, number format, a
/// value that is not finite) otherwise.
std::optional<Sample> decodeSample(const Message& m, Problem& problem);
/// The body of the sample's output line (VNYMR, VNIMU or VNYPR), as the device formats it.
std::string encodeSample(const Sample& s);
/// The bytes of a wide line of output `type` (framing included): what a baud rate must carry.
std::size_t lineBytes(int type);

/// Angular rate [rad/s] and specific force [m/s^2] in REP-103: y and z negated.
struct Rep103 {
  std::array<double, 3> gyro{}, accel{};
};
Rep103 toRep103(const Sample& s);
/// The other way (the emulator's side): REP-103 vectors into the VN-100 body frame.
std::array<double, 3> fromRep103(const std::array<double, 3>& v);

/// Splits a byte stream into lines from '$' to LF (a CR before it dropped). Bytes in any chunks;
/// bytes outside lines are skipped and counted. A line that a new '$' interrupts, or that grows
/// past `max_length` bytes, comes out `cut`.
class LineSplitter {
 public:
  struct Line {
    std::string text;      ///< from '$', without CR LF
    std::size_t tail = 0;  ///< bytes from the line's '$' to the end of the chunk fed
    bool cut = false;
  };
  explicit LineSplitter(std::size_t max_length = 256) : max_length_(max_length) {}
  std::vector<Line> feed(std::string_view bytes);
  std::uint64_t skippedBytes() const { return skipped_; }

 private:
  std::size_t max_length_;
  std::string line_;
  bool in_line_ = false;
  std::uint64_t skipped_ = 0;
};

}  // namespace tessera::drivers::vn
