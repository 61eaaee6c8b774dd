// DeviceLoop: the I/O thread of every driver actor (docs/architecture.md#device-drivers). It
// owns the device's link (serial or TCP): opens it, polls it and a wake-up event, hands what it
// reads to the driver's protocol session through DeviceHooks and does what each DeviceStep says
// (switch the baud rate, write bytes, log events, drop the link). On any failure (the device
// gone, silent, refusing, sending noise) it closes the link and reopens it with exponential
// back-off; the runtime's threads never wait for the device. Events go to stderr, at most one a
// second. The hooks run on the loop's thread only.
#pragma once

#include <tessera/runtime/actor.hpp>

#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace tessera::drivers {

struct DeviceLinkOptions {
  std::string device;
  int baud = 0;
  double retry_initial_s = 0.5;
  double retry_max_s = 8;
};

/// Throws ConfigError naming `actor`'s option when the device, baud or retry times are wrong.
void checkLinkOptions(const std::string& actor, const DeviceLinkOptions& o);
/// Throws ConfigError unless the runtime runs on the wall clock.
void requireWallClock(const std::string& actor, const ActorContext& ctx);

/// What the session asks of the loop after each call.
struct DeviceStep {
  int switch_baud = 0;              ///< > 0: set the port to this rate, then write `send`
  std::string send;                 ///< bytes to write to the device
  std::vector<std::string> events;  ///< for the log
  bool reconnect = false;           ///< close the link, back off, open it again
  std::string reconnect_reason;
};

struct DeviceHooks {
  std::function<int(int configured)> open_baud;  ///< optional: the rate for the next attempt
  std::function<DeviceStep(Nanos now)> connected;
  /// `read_at`: steadyNow() when the bytes were read (for latency figures).
  std::function<DeviceStep(std::string_view bytes, Nanos now, Nanos read_at)> received;
  /// At least every 50 ms, and right after wake(): timeouts, queued commands.
  std::function<DeviceStep(Nanos now)> tick;
  std::function<void()> disconnected;
  std::function<bool()> streaming;
  /// A count that grows while the device delivers: a session that made progress resets the
  /// back-off.
  std::function<std::int64_t()> progress;
};

class DeviceLoop {
 public:
  DeviceLoop(std::string name, DeviceLinkOptions link, DeviceHooks hooks, ActorContext& ctx);
  ~DeviceLoop();
  DeviceLoop(const DeviceLoop&) = delete;
  DeviceLoop& operator=(const DeviceLoop&) = delete;

  void start();
  void stop();  ///< wakes the thread and joins it
  void wake();  ///< thread-safe: run tick() soon (a command is waiting)
  /// reconnects, open_failures, baud, last_error, cpu_s (the I/O thread).
  void summarize(Summary& out) const;

 private:
  void run();
  bool waitOrStop(double seconds);

  std::string name_;
  DeviceLinkOptions link_;
  DeviceHooks hooks_;
  ActorContext& ctx_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  int wake_fd_ = -1;
  mutable std::mutex stats_mutex_;
  std::int64_t reconnects_ = 0, open_failures_ = 0, baud_ = 0;
  double cpu_s_ = 0;
  std::string last_error_;
};

}  // namespace tessera::drivers
