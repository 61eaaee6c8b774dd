// The iRobot Open Interface (Create 2, Roomba 500/600 series), from its specification: the
// commands a base driver sends and the sensor stream it receives
// (docs/architecture.md#device-drivers). Plain C++, no I/O.
//
// Commands are an opcode byte and its arguments, big endian: Start 128, Safe 131 (the robot
// stops itself on a cliff or a wheel drop), Full 132, Drive Direct 145 (right, left wheel
// velocity int16 [mm/s], -500..500), Stream 148 (count, packet ids), Pause/Resume Stream 150
// (0/1), Stop 173. A stream frame, every 15 ms: 19, the byte count N, N bytes of (packet id,
// data)..., and a checksum byte that makes all the frame's bytes sum to 0 modulo 256.
//
// Packets decoded: 7 bumps and wheel drops (bit 0 bump right, 1 bump left, 2 wheel drop right,
// 3 wheel drop left), 9-12 cliff left, front left, front right, right, 21 charging state, 22
// voltage [mV], 23 current [mA], 25 charge [mAh], 26 capacity [mAh], 43/44 left/right encoder
// counts (uint16, wrapping; 508.8 counts per wheel revolution on a Create 2).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::drivers::oi {

constexpr std::uint8_t kStart = 128, kSafe = 131, kFull = 132, kDriveDirect = 145, kStream = 148,
                       kPauseResume = 150, kStop = 173, kStreamHeader = 19;

/// The packets the driver streams, in this order.
const std::vector<std::uint8_t>& streamedPackets();
/// Data bytes of packet `id`; 0 for a packet this codec does not know.
int packetSize(std::uint8_t id);

/// Drive Direct with wheel velocities [mm/s], clamped to the OI's +-500.
std::string driveDirect(double right_mm_s, double left_mm_s);
/// Stream of `ids`.
std::string streamCommand(const std::vector<std::uint8_t>& ids);

struct SensorFrame {
  bool bump_left = false, bump_right = false;
  bool wheel_drop_left = false, wheel_drop_right = false;
  bool cliff_left = false, cliff_front_left = false, cliff_front_right = false, cliff_right = false;
  std::uint8_t charging_state = 0;
  std::uint16_t voltage_mv = 0;
  std::int16_t current_ma = 0;
  std::uint16_t charge_mah = 0, capacity_mah = 0;
  std::uint16_t left_counts = 0, right_counts = 0;
  bool anyCliff() const {
    return cliff_left || cliff_front_left || cliff_front_right || cliff_right;
  }
};

/// A frame's bytes (the emulator's side) with every streamed packet.
std::string encodeFrame(const SensorFrame& f);

/// Splits the byte stream into sensor frames. Bytes in any chunks; garbage before a header,
/// frames whose checksum fails or whose packets do not parse are skipped and counted, and the
/// search resumes at the next byte 19.
class StreamParser {
 public:
  /// `body_bytes`: the frame body size of the packets asked for (0: any), so that a 19 in noise
  /// is not taken for a frame's start.
  explicit StreamParser(std::size_t body_bytes = 0) : body_bytes_(body_bytes) {}
  std::vector<SensorFrame> feed(std::string_view bytes);
  std::uint64_t skippedBytes() const { return skipped_; }
  std::uint64_t badFrames() const { return bad_; }

 private:
  std::size_t body_bytes_;
  std::string buffer_;
  std::uint64_t skipped_ = 0, bad_ = 0;
};

/// The body size of a frame of `ids`.
std::size_t frameBodyBytes(const std::vector<std::uint8_t>& ids);

/// Unwraps a 16-bit encoder count into a cumulative int64 (the wheel turns less than half the
/// counter's range between two frames: 32767 counts = 64 wheel turns in 15 ms).
class EncoderUnwrap {
 public:
  std::int64_t operator()(std::uint16_t counts);
  void reset() { last_.reset(); }

 private:
  std::optional<std::uint16_t> last_;
  std::int64_t total_ = 0;
};

}  // namespace tessera::drivers::oi
