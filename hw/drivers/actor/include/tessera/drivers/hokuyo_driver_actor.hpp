// HokuyoDriverActor ("hokuyo_scip"): a Hokuyo URG/UTM laser over SCIP 2.0, on a serial port,
// a USB-ACM device or TCP (docs/architecture.md#device-drivers).
//
// Publishes (local topic name):
//   scan  msg::LaserScan  frame frame_id, angles from the sensor's PP geometry, ranges [m]
//                         (+inf no return, NaN error code), intensities with `client.intensity`;
//                         stamped with the sensor's own clock mapped to host time (SensorClock)
//
// The device is owned by one I/O thread: it opens the link, runs the SCIP session
// (ScipClient), publishes each good scan as soon as its last byte is read, and on any failure
// (the device gone, silent, refusing, sending noise) closes the link and reopens it with
// exponential back-off. The runtime's threads never wait for the device. A corrupt reply is
// counted and dropped, never published. Needs the wall clock (`clock: wall`): device time is
// real time.
#pragma once

#include <tessera/drivers/scip_client.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace tessera::drivers {

struct HokuyoDriverOptions {
  std::string device = "/dev/ttyACM0";
  int baud = 115200;
  std::string frame_id = "laser";
  std::vector<double> mount = {0, 0, 0};
  double retry_initial_s = 0.5;
  double retry_max_s = 8;
  ScipClientOptions client;

  template <class V>
  void visit(V& v) {
    v("device", device,
      "serial device (/dev/ttyACM0, /dev/serial/by-id/...) or tcp://HOST:PORT (UTM, Ethernet)");
    v("baud", baud, "serial baud rate (URG-04LX RS-232: 19200 at power-up; USB ignores it)");
    v("frame_id", frame_id, "frame of the scans");
    v("mount", mount, "laser pose in base_link [x m, y m, theta rad]");
    v("retry_initial_s", retry_initial_s, "[s] first wait before reopening a failed device");
    v("retry_max_s", retry_max_s, "[s] longest wait between reopen attempts (doubling)");
    v("client", client, "SCIP session: steps, clustering, intensities, timeouts");
  }
};

class HokuyoDriverActor final : public Actor {
 public:
  explicit HokuyoDriverActor(HokuyoDriverOptions options);  // throws ConfigError
  ~HokuyoDriverActor() override;

  void configure(ActorContext& ctx) override;
  void start() override;
  void stop() override;
  /// scans_published, sessions, reconnects, open_failures, bad_replies, refusals,
  /// garbage_bytes, latency_ms_median / _p99 (the last 4096 scans) / _max (last byte read to
  /// published),
  /// clock_offset_ms, cpu_s (the I/O thread), model, last_error.
  void summarize(Summary& out) const override;

 private:
  void run();
  bool waitOrStop(double seconds);
  void publish(const LaserReading& r);

  HokuyoDriverOptions options_;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::LaserScan> scan_pub_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  int wake_fd_ = -1;

  mutable std::mutex stats_mutex_;
  struct Stats {
    std::int64_t published = 0, reconnects = 0, open_failures = 0;
    ScipClient::Counters client;
    std::vector<double> latency_ms;
    double clock_offset_ms = 0, cpu_s = 0, latency_max_ms = 0;
    std::string model, last_error;
  } stats_;
};

}  // namespace tessera::drivers
