// DeviceFaults: see device_faults.hpp.
#include <tessera/drivers/device_faults.hpp>

#include <vector>

namespace tessera::drivers {

void damage(std::string& bytes, const DeviceFaults& faults, std::mt19937_64& rng, int keep) {
  std::uniform_real_distribution<double> u(0, 1);
  if (faults.corrupt_probability > 0 && u(rng) < faults.corrupt_probability) {
    std::vector<std::size_t> at;
    for (std::size_t k = 0; k < bytes.size(); ++k)
      if (keep < 0 || bytes[k] != static_cast<char>(keep)) at.push_back(k);
    if (!at.empty()) {
      // Adding 1..62 to a byte changes it and, since it is not a multiple of 64, any 6-bit
      // checksum over it too.
      const std::size_t k = at[rng() % at.size()];
      bytes[k] = static_cast<char>(static_cast<unsigned char>(bytes[k]) + 1 + rng() % 62);
      if (keep >= 0 && bytes[k] == static_cast<char>(keep)) bytes[k] ^= 0x40;
    }
  }
  if (faults.garbage_probability > 0 && u(rng) < faults.garbage_probability) {
    std::string noise(1 + rng() % 40, '\0');
    for (auto& c : noise) c = static_cast<char>(rng() % 256);
    if (keep >= 0) noise += static_cast<char>(keep);
    bytes = noise + bytes;
  }
}

}  // namespace tessera::drivers
