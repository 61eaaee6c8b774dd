// HokuyoDriverActor ("hokuyo_scip"): a Hokuyo URG/UTM laser over SCIP 2.0, on a serial port,
// a USB-ACM device or TCP (docs/architecture.md#device-drivers).
//
// Publishes (local topic name):
//   scan  msg::LaserScan  frame frame_id, angles from the sensor's PP geometry, ranges [m]
//                         (+inf no return, NaN error code), intensities with `client.intensity`;
//                         stamped with the sensor's own clock mapped to host time (SensorClock)
//
// The device is owned by a LaserDriverLoop (one I/O thread, reconnect with back-off) running
// the SCIP session (ScipClient). A corrupt reply is counted and dropped, never published. Needs
// the wall clock (`clock: wall`): device time is real time.
#pragma once

#include <tessera/drivers/laser_driver_loop.hpp>
#include <tessera/drivers/scip_client.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <memory>
#include <string>
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

class HokuyoDriverActor final : public LaserDriverActor {
 public:
  explicit HokuyoDriverActor(HokuyoDriverOptions options);  // throws ConfigError
};

}  // namespace tessera::drivers
