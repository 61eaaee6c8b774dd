// Test helper: an emulated serial device and a driver's session wired together in memory on a
// simulated clock stepped in 1 ms, each end at its own baud rate, for the sessions that search
// for the device's rate and switch it (sick_lms_test, vectornav_test). What one end sends at a
// rate the other is not at arrives as noise, so each hears the other only at the same rate.
#pragma once

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

namespace tessera::test {

/// The wire, the clock and what the session said. `Bench` derives from it (CRTP) and has
/// `device` (the emulator), `session()`, `openBaud()` (the rate the link opens at) and
/// `collect(output)` (keeps an output's readings); its `lost()`, if it has one, runs when the
/// session asks for a reconnect, which connect() answers `reconnect_delay_ns` later.
template <class Bench>
struct SerialBench {
  static constexpr std::int64_t kStepNs = 1'000'000;

  void connect() {
    link_baud = bench().openBaud();
    exchange(bench().session().connected(now));
  }
  void run(std::int64_t duration_ns) {
    const std::int64_t end = now + duration_ns;
    while (now < end) {
      now += kStepNs;
      const int device_baud = bench().device.baud();  // the rate these bytes go out at
      std::string out = bench().device.poll(now);
      if (!out.empty()) {
        if (link_baud != device_baud) out = std::string(out.size(), '\xf0');
        exchange(bench().session().received(out, now));
      }
      exchange(bench().session().tick(now));
      if (reconnect_pending && now >= reconnect_at) {
        reconnect_pending = false;
        connect();
      }
    }
  }
  /// Does what one output of the session says, as its driver does.
  template <class Output>
  void exchange(Output out) {
    if (out.switch_baud > 0) link_baud = out.switch_baud;
    auto& device = bench().device;
    if (!out.send.empty() && link_baud == device.baud()) device.receive(out.send, now);
    bench().collect(out);
    for (auto& e : out.events) events.push_back(e);
    if (out.reconnect) {
      ++reconnects;
      reason = out.reconnect_reason;
      bench().lost();
      reconnect_pending = true;
      reconnect_at = now + reconnect_delay_ns;
    }
  }
  void lost() {}  // a Bench that has its own hides this one
  bool said(const std::string& what) const {
    return std::any_of(events.begin(), events.end(),
                       [&](const std::string& e) { return e.find(what) != std::string::npos; });
  }

  int link_baud = 0;
  std::int64_t now = 1000 * kStepNs;
  std::int64_t reconnect_delay_ns = 0;
  std::vector<std::string> events;
  int reconnects = 0;
  std::string reason;

 private:
  Bench& bench() { return static_cast<Bench&>(*this); }
  bool reconnect_pending = false;
  std::int64_t reconnect_at = 0;
};

}  // namespace tessera::test
