// SickLmsClient: the host side of a session with a SICK LMS200/291 as a LaserSession, no I/O
// (docs/architecture.md#device-drivers).
//
// The LMS powers up at 9600 baud and keeps whatever rate a session switched it to until it
// loses power, so the client looks for it: each attempt opens the port at the next rate of
// (session baud, 9600, 19200, 38400, 500000) until one answers. Session: stop streaming (0x20
// 0x25), switch to the session baud (0x20 + rate; the port follows), set the variant (scan angle,
// resolution: 0x3B), read the configuration (0x74) and, when its units are not the ones asked
// for, write them (installation mode, 0x77), then stream every scan (0x20 0x24). A NAK, a
// refusal or no reply within reply_timeout_s asks for a reconnect; so does no good scan within
// scan_timeout_s while streaming. Scans that fail their CRC or decoding are counted, never
// returned.
//
// Scans: angle/resolution + 1 beams from -angle/2 (right) counter-clockwise, metres; values from
// 8183 up (the sensor's no-echo and overflow codes) are +inf. The LMS sends no timestamp, so a
// scan is stamped when its telegram began to arrive: its last byte's time minus the telegram's
// transfer time at the session baud.
#pragma once

#include <tessera/drivers/laser_session.hpp>
#include <tessera/drivers/sick_lms.hpp>

#include <cstdint>
#include <string>
#include <string_view>

namespace tessera::drivers {

struct SickLmsClientOptions {
  int angle_deg = 180;           ///< scan angle: 100 or 180
  double resolution_deg = 1.0;   ///< 0.25 (angle 100 only), 0.5 or 1
  std::string units = "mm";      ///< mm (8 m range, mm resolution) or cm (80 m, cm)
  double reply_timeout_s = 1.0;  ///< longest wait for a command's reply
  double scan_timeout_s = 1.0;   ///< streaming: longest wait for a good scan

  template <class V>
  void visit(V& v) {
    v("angle_deg", angle_deg, "scan angle [deg]: 100 or 180");
    v("resolution_deg", resolution_deg, "angular resolution [deg]: 0.25 (100 deg only), 0.5, 1");
    v("units", units, "mm (8 m range) or cm (80 m range); written to the sensor if it differs");
    v("reply_timeout_s", reply_timeout_s, "[s] longest wait for a command's reply");
    v("scan_timeout_s", scan_timeout_s, "[s] streaming: longest wait for a good scan");
  }
};

class SickLmsClient final : public LaserSession {
 public:
  /// `session_baud`: the rate to run at (9600, 19200, 38400 or 500000 on RS-422). Throws
  /// std::invalid_argument for options the LMS does not have.
  SickLmsClient(SickLmsClientOptions options, int session_baud);

  int openBaud(int configured) override;
  SessionOutput connected(std::int64_t now_ns) override;
  void disconnected() override;
  SessionOutput received(std::string_view bytes, std::int64_t now_ns) override;
  SessionOutput tick(std::int64_t now_ns) override;
  bool streaming() const override { return step_ == Step::kStreaming; }
  SessionCounters counters() const override;
  std::string model() const override;

 private:
  enum class Step {
    kIdle,
    kStop,
    kBaud,
    kVariant,
    kReadConfig,
    kInstall,
    kWriteConfig,
    kStart,
    kStreaming
  };
  void send(SessionOutput& out, Step step, const std::string& payload, std::int64_t now_ns);
  void onTelegram(const sick::Telegram& t, std::int64_t now_ns, SessionOutput& out);
  void onScan(const sick::Telegram& t, std::int64_t now_ns, SessionOutput& out);
  void next(SessionOutput& out, std::int64_t now_ns);
  void fail(SessionOutput& out, const std::string& why);
  static const char* stepName(Step s);

  SickLmsClientOptions options_;
  int session_baud_;
  int resolution_centideg_ = 100;
  std::size_t beams_ = 181;
  int attempt_ = 0;    // index into the baud search
  int link_baud_ = 0;  // the rate the port is at now
  Step step_ = Step::kIdle;
  std::int64_t deadline_ns_ = 0;
  std::string config_;  // the 0x74 block
  sick::TelegramParser parser_;
  SessionCounters counters_;
  std::uint64_t garbage_before_ = 0, session_items_ = 0;
};

}  // namespace tessera::drivers
