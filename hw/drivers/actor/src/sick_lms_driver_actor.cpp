#include <tessera/drivers/sick_lms_driver_actor.hpp>

#include <tessera/runtime/registry.hpp>

namespace tessera::drivers {

SickLmsDriverActor::SickLmsDriverActor(SickLmsDriverOptions o)
    : LaserDriverActor("sick_lms", {o.device, o.baud, o.retry_initial_s, o.retry_max_s}, o.frame_id,
                       o.mount) {
  try {
    session_ = std::make_unique<SickLmsClient>(o.client, o.baud);
  } catch (const std::invalid_argument& e) {
    fail(std::string(e.what()).find("baud") != std::string::npos ? "baud" : "client", e.what());
  }
}

TESSERA_REGISTER_ACTOR("sick_lms", SickLmsDriverActor, SickLmsDriverOptions,
                       "SICK LMS200/291 laser over its RS-232/RS-422 telegrams");

}  // namespace tessera::drivers
