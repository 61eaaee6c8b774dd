#include <tessera/drivers/hokuyo_driver_actor.hpp>

#include <tessera/runtime/registry.hpp>

namespace tessera::drivers {

HokuyoDriverActor::HokuyoDriverActor(HokuyoDriverOptions o)
    : LaserDriverActor("hokuyo_scip", {o.device, o.baud, o.retry_initial_s, o.retry_max_s},
                       o.frame_id, o.mount) {
  try {
    session_ = std::make_unique<ScipClient>(o.client);
  } catch (const std::invalid_argument& e) {
    fail("client", e.what());
  }
}

TESSERA_REGISTER_ACTOR("hokuyo_scip", HokuyoDriverActor, HokuyoDriverOptions,
                       "Hokuyo URG/UTM laser over SCIP 2.0 (serial, USB-ACM or TCP)");

}  // namespace tessera::drivers
