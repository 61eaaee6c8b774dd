// LaserDriverLoop: the I/O thread every laser driver actor runs (docs/architecture.md#device-
// drivers). It owns the device's link, drives a LaserSession (the protocol core) with what it
// reads, and publishes each good scan from its own thread as soon as the scan's last byte is
// read. On any failure (the device gone, silent, refusing, sending noise) it closes the link
// and reopens it with exponential back-off; the runtime's threads never wait for the device.
// Events go to stderr, at most one a second.
#pragma once

#include <tessera/drivers/laser_session.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace tessera::drivers {

struct LaserLinkOptions {
  std::string device;
  int baud = 0;
  double retry_initial_s = 0.5;
  double retry_max_s = 8;
};

/// Throws ConfigError naming `actor`'s option when the device, baud or retry times are wrong.
void checkLaserLinkOptions(const std::string& actor, const LaserLinkOptions& o);
/// Throws ConfigError unless the runtime runs on the wall clock.
void requireWallClock(const std::string& actor, const ActorContext& ctx);

class LaserDriverLoop {
 public:
  /// `session` and `ctx` outlive the loop. Scans are published on `scan` with `frame_id` and
  /// the mount [x, y, theta].
  LaserDriverLoop(std::string name, LaserLinkOptions link, LaserSession& session, ActorContext& ctx,
                  Publisher<msg::LaserScan> scan, std::string frame_id, std::vector<double> mount);
  ~LaserDriverLoop();
  LaserDriverLoop(const LaserDriverLoop&) = delete;
  LaserDriverLoop& operator=(const LaserDriverLoop&) = delete;

  void start();
  void stop();  ///< wakes the thread and joins it
  /// scans_published, sessions, reconnects, open_failures, bad_replies, refusals,
  /// garbage_bytes, latency_ms_median / _p99 (the last 4096 scans) / _max (last byte read to
  /// published), stamp_minus_receive_ms, cpu_s (the I/O thread), model, baud, last_error.
  void summarize(Summary& out) const;

 private:
  void run();
  bool waitOrStop(double seconds);
  void publish(const LaserReading& r);

  std::string name_;
  LaserLinkOptions link_;
  LaserSession& session_;
  ActorContext& ctx_;
  Publisher<msg::LaserScan> scan_pub_;
  std::string frame_id_;
  std::vector<double> mount_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  int wake_fd_ = -1;

  mutable std::mutex stats_mutex_;
  struct Stats {
    std::int64_t published = 0, reconnects = 0, open_failures = 0, baud = 0;
    SessionCounters session;
    std::vector<double> latency_ms;
    double clock_offset_ms = 0, cpu_s = 0, latency_max_ms = 0;
    std::string model, last_error;
  } stats_;
};

/// What a laser driver actor is, given its session: it checks the link options and the mount,
/// needs the wall clock, advertises `scan` and runs a LaserDriverLoop from start() to stop().
class LaserDriverActor : public Actor {
 public:
  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  /// LaserDriverLoop's figures: scans_published, reconnects, bad_replies, latency_ms_*, …
  void summarize(Summary& out) const override;

 protected:
  /// Throws ConfigError naming `name`'s option ('device', 'baud', 'mount', …).
  LaserDriverActor(std::string name, LaserLinkOptions link, std::string frame_id,
                   std::vector<double> mount);
  ~LaserDriverActor() override;
  /// The derived driver's session; set in its constructor.
  std::unique_ptr<LaserSession> session_;
  [[noreturn]] void fail(const std::string& key, const std::string& what) const;

 private:
  std::string name_;
  LaserLinkOptions link_;
  std::string frame_id_;
  std::vector<double> mount_;
  std::unique_ptr<LaserDriverLoop> loop_;
};

}  // namespace tessera::drivers
