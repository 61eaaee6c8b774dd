// tessera_fuzz: a mutation fuzzer for the dataset parsers that needs no special compiler.
// Seeds are real dataset files (their first --max-lines lines), mutated by tests/hw/datasets/
// mutate.hpp; any exception other than DatasetError, or a crash, is a failure and the input is
// saved. For coverage-guided fuzzing build the libFuzzer targets instead (see fuzz_targets.hpp).
#include "../hw/datasets/mutate.hpp"
#include "fuzz_targets.hpp"

#include <tessera/io/text_reader.hpp>

#include <CLI/CLI.hpp>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>

namespace fs = std::filesystem;
using tessera::fuzz::Target;

namespace {

std::string head(const fs::path& path, std::size_t max_lines) {
  tessera::io::TextReader reader(path);
  std::string text, line;
  for (std::size_t n = 0; n < max_lines && reader.next(line); ++n) text += line + "\n";
  return text;
}

struct Run {
  std::uint64_t inputs = 0;
  bool ok = true;
};

Run fuzz(const Target& target, const std::vector<std::string>& seeds, double seconds,
         std::uint64_t seed) {
  tessera::test::Mutator mutator(seed);
  Run run;
  const auto start = std::chrono::steady_clock::now();
  const auto budget = std::chrono::duration<double>(seconds);
  // Every seed once unmutated: a valid file must parse without anything escaping.
  for (const auto& s : seeds) {
    ++run.inputs;
    if (!tessera::fuzz::runOne(target, s)) return run.ok = false, run;
  }
  while (std::chrono::steady_clock::now() - start < budget) {
    for (int k = 0; k < 16; ++k) {
      const std::string& s = seeds[run.inputs % seeds.size()];
      const std::string input = mutator.mutate(s);
      ++run.inputs;
      if (!tessera::fuzz::runOne(target, input)) {
        const std::string file = std::string("fuzz-failure-") + target.name + ".txt";
        std::ofstream(file, std::ios::binary) << input;
        std::cerr << "input saved to " << file << "\n";
        run.ok = false;
        return run;
      }
    }
  }
  return run;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Mutation fuzzer for Tessera's dataset parsers"};
  std::string name;
  std::vector<std::string> files;
  double seconds = 10;
  std::uint64_t seed = 1;
  std::size_t max_lines = 0;
  bool list = false;
  app.add_option("target", name, "parser to fuzz, or 'all'");
  app.add_option("files", files,
                 "seed files (default: the target's files in ../shared/data, else a built-in "
                 "example)");
  app.add_option("--seconds", seconds, "how long to fuzz each target");
  app.add_option("--seed", seed, "random seed of the mutations");
  app.add_option("--max-lines", max_lines,
                 "lines taken from the start of each seed file (default: per target)");
  app.add_flag("--list", list, "list the targets");
  CLI11_PARSE(app, argc, argv);

  const auto& all = tessera::fuzz::targets();
  if (list || name.empty()) {
    for (const auto& t : all) std::cout << t.name << "\t" << t.description << "\n";
    return name.empty() && !list ? 2 : 0;
  }
  std::vector<const Target*> chosen;
  if (name == "all") {
    for (const auto& t : all) chosen.push_back(&t);
  } else if (const Target* t = tessera::fuzz::findTarget(name)) {
    chosen.push_back(t);
  } else {
    std::cerr << "error: unknown target '" << name << "' (see --list)\n";
    return 2;
  }
  bool ok = true;
  for (const Target* t : chosen) {
    std::vector<std::string> seeds;
    std::string origin;
    const std::size_t lines = max_lines > 0 ? max_lines : t->seed_lines;
    try {
      if (!files.empty()) {
        for (const auto& f : files) seeds.push_back(head(f, lines));
        origin = "given files";
      } else {
        for (const auto& rel : t->shared_data_seeds) {
          const fs::path p = fs::path(TESSERA_SHARED_DATA_DIR) / rel;
          if (fs::exists(p)) seeds.push_back(head(p, lines));
        }
        origin = seeds.empty() ? "built-in example (../shared/data absent)" : "../shared/data";
      }
    } catch (const std::exception& e) {
      std::cerr << "error: cannot read a seed: " << e.what() << "\n";
      return 2;
    }
    if (seeds.empty()) seeds.push_back(t->builtin_seed);
    const auto t0 = std::chrono::steady_clock::now();
    const Run run = fuzz(*t, seeds, seconds, seed);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cout << t->name << ": " << run.inputs << " inputs in " << s << " s ("
              << static_cast<std::uint64_t>(static_cast<double>(run.inputs) / std::max(s, 1e-9))
              << "/s), seeds from " << origin << ": " << (run.ok ? "no failure" : "FAILED")
              << std::endl;
    ok = ok && run.ok;
  }
  return ok ? 0 : 1;
}
