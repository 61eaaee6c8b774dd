// VectorNavImu: the host side of a VectorNav VN-100 IMU on its serial port (ASCII protocol) as a
// state machine, no I/O: bytes in, inertial samples out (docs/architecture.md#device-drivers).
//
// Session: read the model (register 1) to find the device. When nothing sensible comes, try the
// next VN-100 baud rate on the same open port (ImuOutput::switch_baud), so the search costs no
// reconnects; read the serial number (3); switch the device to the session baud (5) when it is
// elsewhere; set the async output type (6: VNIMU or VNYMR) and rate (7); then stream. A command
// whose reply does not come within reply_timeout_s is sent again (three tries); a VNERR reply
// ends the session, naming the code's meaning. No good sample for silence_periods output
// periods asks for a reconnect.
//
// Lines whose checksum, framing or numbers are bad (NaN included) are counted by reason and
// dropped, never returned. Samples are REP-103 (x forward, y left, z up; vectornav.hpp flips the
// VN-100's y right, z down). The VN-100 sends no timestamp in these lines, so a sample is
// stamped when its line's first byte arrived: the time its bytes were read less their transfer
// time at the link's baud rate, and always after the previous sample's stamp (USB and pty reads
// bunch lines). Time is host int64 ns.
#pragma once

#include <tessera/drivers/vectornav.hpp>

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::drivers {

struct VectorNavOptions {
  vn::Output output = vn::Output::kImu;
  int rate_hz = 100;
  double reply_timeout_s = 0.3;
  int silence_periods = 20;

  template <class V>
  void visit(V& v) {
    v("output", output,
      "async output: imu (VNIMU: calibrated rates and acceleration, temperature, pressure) or "
      "ymr (VNYMR: the attitude filter's bias-compensated values, yaw/pitch/roll)");
    v("rate_hz", rate_hz, "[Hz] output rate: 1, 2, 4, 5, 10, 20, 25, 40, 50, 100 or 200");
    v("reply_timeout_s", reply_timeout_s, "[s] longest wait for a command's reply");
    v("silence_periods", silence_periods, "no good sample for this many output periods: reconnect");
  }
};

struct ImuReading {
  std::int64_t stamp_ns = 0;      ///< host time the line's first byte arrived (estimated)
  std::int64_t received_ns = 0;   ///< host time its last byte was read
  std::array<double, 3> gyro{};   ///< [rad/s] REP-103
  std::array<double, 3> accel{};  ///< [m/s^2] REP-103 specific force (+g on z at rest)
};

struct ImuOutput {
  int switch_baud = 0;  ///< > 0: set the port to this rate, then write `send`
  std::string send;
  std::vector<ImuReading> samples;
  std::vector<std::string> events;
  bool reconnect = false;
  std::string reconnect_reason;
};

class VectorNavImu {
 public:
  /// `session_baud`: the rate to stream at (a VN-100 rate termios has: 9600 .. 921600 but not
  /// 128000) with room for the output. Throws std::invalid_argument.
  VectorNavImu(VectorNavOptions options, int session_baud);

  /// The rate to open the port at: the session's (the VN-100 keeps a rate until power-off).
  int openBaud() const { return session_baud_; }
  ImuOutput connected(std::int64_t now_ns);
  void disconnected();
  ImuOutput received(std::string_view bytes, std::int64_t now_ns);
  /// Timeouts; call it at least every 100 ms.
  ImuOutput tick(std::int64_t now_ns);

  bool streaming() const { return step_ == Step::kStreaming; }
  struct Counters {
    std::int64_t samples = 0, sessions = 0, device_errors = 0;
    std::int64_t truncated = 0, malformed = 0, bad_checksum = 0, not_finite = 0;
    std::uint64_t garbage_bytes = 0;
    std::int64_t badLines() const { return truncated + malformed + bad_checksum + not_finite; }
  };
  Counters counters() const;
  /// "VN-100T-CR, serial 0100012345" once the device said so; "" before.
  std::string model() const;

 private:
  enum class Step { kIdle, kModel, kSerial, kBaud, kType, kRate, kStreaming };
  void send(ImuOutput& out, Step step, std::int64_t now_ns);
  void next(ImuOutput& out, std::int64_t now_ns);
  void onMessage(const vn::Message& m, std::size_t tail, std::int64_t now_ns, ImuOutput& out);
  void bad(const vn::Problem& p, ImuOutput& out);
  void fail(ImuOutput& out, const std::string& why);
  std::string stepName(Step s) const;
  double silenceSeconds() const {
    return options_.silence_periods / static_cast<double>(options_.rate_hz);
  }

  VectorNavOptions options_;
  int session_baud_;
  int type_;
  Step step_ = Step::kIdle;
  std::int64_t deadline_ns_ = 0, last_stamp_ns_ = 0;
  int tries_ = 0;
  std::vector<int> search_;    // baud rates to try, the session's first
  std::size_t search_at_ = 0;  // index of the rate the port is at now
  bool heard_ = false;         // a good line came at this rate
  std::string model_, serial_;
  vn::LineSplitter splitter_;
  Counters counters_;
  std::uint64_t garbage_before_ = 0;
};

}  // namespace tessera::drivers
