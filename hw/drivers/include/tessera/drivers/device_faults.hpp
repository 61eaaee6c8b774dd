// DeviceFaults: what an emulated device can do wrong, and the byte-level damage shared by the
// emulators (ScipDevice, SickLmsDevice): garbage before a reply, a changed byte inside it
// (docs/architecture.md#device-drivers).
#pragma once

#include <cstdint>
#include <random>
#include <string>

namespace tessera::drivers {

struct DeviceFaults {
  double garbage_probability = 0;  ///< per reply: random bytes sent before it
  double corrupt_probability = 0;  ///< per reply: one byte changed (its checksum fails)
  bool silent = false;             ///< reads commands, answers nothing
  double reply_delay_s = 0;        ///< every reply held back this long
};

/// Applies the garbage and corruption faults to one reply. `keep` bytes are never changed (a
/// line feed, which would only split a SCIP line rather than damage it); -1 = none.
void damage(std::string& bytes, const DeviceFaults& faults, std::mt19937_64& rng, int keep = -1);

}  // namespace tessera::drivers
