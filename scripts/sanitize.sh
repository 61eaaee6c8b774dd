#!/usr/bin/env bash
# AddressSanitizer + UndefinedBehaviorSanitizer run of the unit tests (cores, runtime, messages,
# parsers): a separate build in build-asan/, then every unit test in one process. Any report
# (leak, overflow, use after free, undefined behaviour) fails the run.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -f build-asan/CMakeCache.txt ]; then
  cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTESSERA_SANITIZE=ON
fi
cmake --build build-asan -j "$(nproc)" --target tessera_unit_tests
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
build-asan/bin/tessera_unit_tests "$@"
