// LaserDriverLoop and LaserDriverActor: a laser driver is a DeviceLoop running a LaserSession
// (the protocol core), publishing its scans (docs/architecture.md#device-drivers).
#pragma once

#include <tessera/drivers/device_loop.hpp>
#include <tessera/drivers/laser_session.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>

#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace tessera::drivers {

/// A DeviceLoop running a LaserSession: publishes each scan from the I/O thread as soon as its
/// last byte is read, on `scan` with `frame_id` and the mount [x, y, theta].
class LaserDriverLoop {
 public:
  /// `session` and `ctx` outlive the loop.
  LaserDriverLoop(std::string name, DeviceLinkOptions link, LaserSession& session,
                  ActorContext& ctx, Publisher<msg::LaserScan> scan, std::string frame_id,
                  std::vector<double> mount);
  void start() { loop_->start(); }
  void stop() { loop_->stop(); }
  /// DeviceLoop's figures and scans_published, sessions, bad_replies, refusals, garbage_bytes,
  /// latency_ms_median / _p99 (the last 4096 scans) / _max (last byte read to published),
  /// stamp_minus_receive_ms, model.
  void summarize(Summary& out) const;

 private:
  DeviceStep take(SessionOutput&& out, Nanos read_at);
  void publish(const LaserReading& r);

  LaserSession& session_;
  Publisher<msg::LaserScan> scan_pub_;
  std::string frame_id_;
  std::vector<double> mount_;
  mutable std::mutex stats_mutex_;
  struct Stats {
    std::int64_t published = 0;
    SessionCounters session;
    std::vector<double> latency_ms;
    double clock_offset_ms = 0, latency_max_ms = 0;
    std::string model;
  } stats_;
  std::unique_ptr<DeviceLoop> loop_;  // last: its thread uses the members above
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
  LaserDriverActor(std::string name, DeviceLinkOptions link, std::string frame_id,
                   std::vector<double> mount);
  ~LaserDriverActor() override;
  /// The derived driver's session; set in its constructor.
  std::unique_ptr<LaserSession> session_;
  [[noreturn]] void fail(const std::string& key, const std::string& what) const;

 private:
  std::string name_;
  DeviceLinkOptions link_;
  std::string frame_id_;
  std::vector<double> mount_;
  std::unique_ptr<LaserDriverLoop> loop_;
};

}  // namespace tessera::drivers
