// EmulatorHost: runs an emulated device (ScipDevice, …) on a pseudo-terminal or a TCP port in
// its own thread, so a driver can be tested against it, or the stack run on a recorded log
// without hardware (docs/architecture.md#device-drivers).
//
// The host moves bytes between the port and the device at the device's pace. It can unplug the
// device (the driver's descriptor hangs up; it comes back after `down_s`), and it models a
// wrong baud rate: when the driver set the pseudo-terminal to another rate than the device's,
// the device hears noise and answers noise, as a UART would.
#pragma once

#include <tessera/drivers/byte_link.hpp>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>

namespace tessera::drivers {

/// What the host needs of a device: bytes in, bytes due out, and when the next ones are due.
struct EmulatedDevice {
  std::function<void(std::string_view, std::int64_t)> receive;
  std::function<std::string(std::int64_t)> poll;
  std::function<std::optional<std::int64_t>()> next_due;
  std::function<void(std::int64_t)> restart;  ///< optional: called when plugged back in
  std::function<int()> baud;  ///< optional: the device's rate now, if it changes (else options)
};

struct EmulatorHostOptions {
  std::string link;   ///< pty: a symlink to create for the device (stable across unplugs)
  int tcp_port = -1;  ///< >= 0: listen on 127.0.0.1:port instead of a pty (0: any free port)
  int baud = 115200;  ///< the device's rate (pty only)
};

class EmulatorHost {
 public:
  /// `device` is only called from the host's thread, or under the host's lock (withDevice).
  EmulatorHost(EmulatedDevice device, EmulatorHostOptions options);
  ~EmulatorHost();  // stops the thread
  EmulatorHost(const EmulatorHost&) = delete;
  EmulatorHost& operator=(const EmulatorHost&) = delete;

  /// What a driver opens: the pty's path (or its link), or "tcp://127.0.0.1:PORT".
  std::string devicePath() const;
  /// Unplugs the device for `down_s` seconds, then plugs it back in (restarted).
  void unplug(double down_s);
  /// Runs `f` while the host's thread is not touching the device, and returns what it returns:
  /// the only safe way to change a running device's faults or read its state from elsewhere.
  template <class F>
  auto withDevice(F&& f) {
    std::lock_guard lock(mutex_);
    return f();
  }
  std::int64_t bytesIn() const { return bytes_in_; }
  std::int64_t bytesOut() const { return bytes_out_; }
  std::int64_t plugs() const { return plugs_; }

 private:
  void run();
  void serveOnce();
  EmulatedDevice device_;
  EmulatorHostOptions options_;
  std::unique_ptr<PseudoTerminal> pty_;
  int listen_fd_ = -1, client_fd_ = -1, port_ = -1;
  int wake_fd_ = -1;
  std::mutex mutex_;
  std::atomic<bool> stop_{false};
  std::atomic<std::int64_t> unplug_until_{0}, unplug_request_{0};
  std::atomic<std::int64_t> bytes_in_{0}, bytes_out_{0}, plugs_{0};
  std::thread thread_;
};

/// Host time for emulators and drivers: CLOCK_REALTIME in ns, as the runtime's wall clock.
std::int64_t hostNowNs();

}  // namespace tessera::drivers
