// SickLmsDriverActor ("sick_lms"): a SICK LMS200/291 laser on RS-232 or RS-422
// (docs/architecture.md#device-drivers).
//
// Publishes (local topic name):
//   scan  msg::LaserScan  frame frame_id, 181/361/401 beams from -angle/2 counter-clockwise,
//                         ranges [m] (+inf no echo), stamped when the scan's telegram began
//                         to arrive
//
// A LaserDriverLoop (one I/O thread, reconnect with back-off) runs the LMS session
// (SickLmsClient): it finds the sensor's baud rate, switches it to `baud`, sets the variant and
// units and streams every scan the line can carry (500 kBd: all 75 a second). Needs the wall
// clock (`clock: wall`).
#pragma once

#include <tessera/drivers/laser_driver_loop.hpp>
#include <tessera/drivers/sick_lms_client.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <memory>
#include <string>
#include <vector>

namespace tessera::drivers {

struct SickLmsDriverOptions {
  std::string device = "/dev/ttyUSB0";
  int baud = 38400;
  std::string frame_id = "laser";
  std::vector<double> mount = {0, 0, 0};
  double retry_initial_s = 0.5;
  double retry_max_s = 8;
  SickLmsClientOptions client;

  template <class V>
  void visit(V& v) {
    v("device", device, "serial device (/dev/ttyUSB0, /dev/serial/by-id/...)");
    v("baud", baud,
      "session baud rate: 9600, 19200, 38400 (RS-232: ~10 scans/s at 1 deg) or 500000 (RS-422: "
      "all 75 scans/s); the LMS is found at whatever rate it is at and switched");
    v("frame_id", frame_id, "frame of the scans");
    v("mount", mount, "laser pose in base_link [x m, y m, theta rad]");
    v("retry_initial_s", retry_initial_s, "[s] first wait before reopening a failed device");
    v("retry_max_s", retry_max_s, "[s] longest wait between reopen attempts (doubling)");
    v("client", client, "LMS session: variant, units, timeouts");
  }
};

class SickLmsDriverActor final : public LaserDriverActor {
 public:
  explicit SickLmsDriverActor(SickLmsDriverOptions options);  // throws ConfigError
};

}  // namespace tessera::drivers
