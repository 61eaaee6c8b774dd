// ScipClient: the host side of a SCIP 2.0 session with a Hokuyo laser, as a state machine with
// no I/O (docs/architecture.md#device-drivers). The driver actor owns the port; it tells the
// client when the link is up, hands it every byte it reads and ticks it, and does what the
// client's Output says: write bytes, publish scans, log events, or drop the link and reconnect.
//
// Session: "SCIP2.0" (switches a URG-04LX out of SCIP 1.1; "0E" = already in 2.0), "QT" (stops a
// stream left running by an earlier session), "PP" (geometry and range limits), then "MD" (or
// "ME" with intensities) streams scans until the link drops. Scan replies are matched by their
// echo; a reply that fails its checksum or decoding is counted and dropped, never published.
// No reply to a handshake command within reply_timeout_s, or no good scan within
// scan_timeout_s while streaming, asks for a reconnect.
//
// Units: time is host int64 ns; published ranges are metres in the laser frame, angles
// counter-clockwise with 0 ahead (from the sensor's AFRT/ARES).
#pragma once

#include <tessera/drivers/laser_session.hpp>
#include <tessera/drivers/scip.hpp>
#include <tessera/drivers/sensor_clock.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::drivers {

struct ScipClientOptions {
  int first_step = -1;            ///< first step to scan; -1 = the sensor's first (AMIN)
  int last_step = -1;             ///< last step; -1 = the sensor's last (AMAX)
  int cluster = 1;                ///< adjacent steps merged into one beam (1..99)
  bool intensity = false;         ///< ME instead of MD: intensities with the ranges
  bool zero_is_no_return = true;  ///< a 0 reading is no return (+inf), else an error (NaN)
  double reply_timeout_s = 1.0;   ///< handshake: a command's reply must come within this
  double scan_timeout_s = 1.0;    ///< streaming: a good scan must come within this
  double clock_window_s = 10.0;   ///< SensorClock's offset window

  template <class V>
  void visit(V& v) {
    v("first_step", first_step, "first step to scan; -1 = the sensor's first (PP AMIN)");
    v("last_step", last_step, "last step to scan; -1 = the sensor's last (PP AMAX)");
    v("cluster", cluster, "adjacent steps merged into one beam, 1..99 (the nearest reading wins)");
    v("intensity", intensity, "stream with intensities (ME) instead of ranges only (MD)");
    v("zero_is_no_return", zero_is_no_return,
      "a 0 reading is no return (+inf); false: an error (NaN)");
    v("reply_timeout_s", reply_timeout_s, "[s] handshake: longest wait for a command's reply");
    v("scan_timeout_s", scan_timeout_s, "[s] streaming: longest wait for a good scan");
    v("clock_window_s", clock_window_s,
      "[s] window of the sensor-to-host clock offset (the fastest transfer in it)");
  }
};

class ScipClient final : public LaserSession {
 public:
  enum class State { kDisconnected, kHandshake, kStreaming };
  using Output = SessionOutput;
  using Counters = SessionCounters;

  explicit ScipClient(ScipClientOptions options);  // throws std::invalid_argument

  Output connected(std::int64_t now_ns) override;
  void disconnected() override;
  Output received(std::string_view bytes, std::int64_t now_ns) override;
  Output tick(std::int64_t now_ns) override;
  bool streaming() const override { return state_ == State::kStreaming; }
  Counters counters() const override;
  std::string model() const override { return parameters_ ? parameters_->model : ""; }

  State state() const { return state_; }
  /// The sensor's PP answer, once the handshake got it.
  const std::optional<scip::SensorParameters>& parameters() const { return parameters_; }
  /// The scan command sent ("MD0044072501000"), without its line feed.
  const std::string& scanEcho() const { return scan_echo_; }

 private:
  void send(Output& out, const std::string& command, std::int64_t now_ns);
  void onReply(const scip::Reply& reply, std::int64_t now_ns, Output& out);
  void onScan(const scip::Reply& reply, std::int64_t now_ns, Output& out);
  void startScans(std::int64_t now_ns, Output& out);
  void fail(Output& out, const std::string& why);

  ScipClientOptions options_;
  State state_ = State::kDisconnected;
  scip::ReplyParser parser_;
  SensorClock clock_;
  std::optional<scip::SensorParameters> parameters_;
  std::string waiting_for_;       // echo of the handshake command in flight
  std::int64_t deadline_ns_ = 0;  // of that reply, or of the next scan while streaming
  std::string scan_echo_;
  int first_ = 0, last_ = 0;
  Counters counters_;
  std::uint64_t garbage_before_ = 0;   // parser's count from earlier sessions
  std::uint64_t session_replies_ = 0;  // replies parsed since connected()
};

}  // namespace tessera::drivers
