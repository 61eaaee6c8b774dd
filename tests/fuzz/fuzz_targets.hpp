// Fuzz targets for every dataset parser: text in, parse, and only DatasetError may come out.
//
// The same table drives two fuzzers:
//   - libFuzzer (clang, -DTESSERA_FUZZ=ON): one binary per target, fuzz_<name>, built from
//     libfuzzer_entry.cpp; run e.g. `build-fuzz/bin/fuzz_carmen -max_total_time=600 corpus/`.
//   - tessera_fuzz (any compiler, always built): a mutation fuzzer over seed files
//     (`tessera_fuzz carmen --seconds 60 ../shared/data/intel-lab-mrpt/intel.clf.gz`); ctest
//     runs each target briefly on the shared datasets, or on the built-in seeds without them.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace tessera::fuzz {

struct Target {
  const char* name;
  const char* description;
  // Parses `text` as the file `name`; throws DatasetError on bad input (anything else is a bug).
  void (*parse)(const std::string& text);
  std::string builtin_seed;                    // a small valid example of the format
  std::vector<std::string> shared_data_seeds;  // relative to ../shared/data
  // Lines taken from the start of each seed file: fewer for formats with very long lines, so
  // a mutated input stays small and the fuzzer fast.
  std::size_t seed_lines = 300;
};

const std::vector<Target>& targets();
const Target* findTarget(std::string_view name);

// Runs one input; returns false (and says why on stderr) if something other than DatasetError
// escaped the parser.
bool runOne(const Target& target, const std::string& text);

}  // namespace tessera::fuzz
