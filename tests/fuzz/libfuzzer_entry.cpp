// libFuzzer entry point for one target, chosen at compile time with -DTESSERA_FUZZ_TARGET="name".
#include "fuzz_targets.hpp"

#include <cstdint>
#include <cstdlib>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const tessera::fuzz::Target* target = tessera::fuzz::findTarget(TESSERA_FUZZ_TARGET);
  if (target == nullptr) std::abort();
  if (!tessera::fuzz::runOne(*target, std::string(reinterpret_cast<const char*>(data), size)))
    std::abort();  // libFuzzer saves the input as a crash
  return 0;
}
