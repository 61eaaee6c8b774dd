// Runs the built `tessera` CLI (TESSERA_CLI_PATH) in a shell and captures exit code, stdout and
// stderr, for end-to-end tests of its commands.
#pragma once

#include <catch2/catch.hpp>

#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace tessera::test {

struct CliRun {
  int exit_code = -1;
  std::string out, err;
};

/// A file's whole contents (bytes as they are), empty when it cannot be read.
inline std::string fileText(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// `tessera ARGS` with stderr captured in dir/stderr.txt.
inline CliRun runCli(const std::string& args, const std::filesystem::path& dir) {
  const std::filesystem::path err_file = dir / "stderr.txt";
  const std::string command =
      std::string(TESSERA_CLI_PATH) + " " + args + " 2>" + err_file.string();
  CliRun run;
  FILE* pipe = ::popen(command.c_str(), "r");
  REQUIRE(pipe != nullptr);
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) run.out.append(buf, n);
  const int status = ::pclose(pipe);
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  run.err = fileText(err_file);
  return run;
}

}  // namespace tessera::test
