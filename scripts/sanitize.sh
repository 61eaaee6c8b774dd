#!/usr/bin/env bash
# AddressSanitizer + UndefinedBehaviorSanitizer run of the unit tests (cores, runtime, messages,
# parsers): a separate build in build-asan/, then every unit test in one process. Any report
# (leak, overflow, use after free, undefined behaviour) fails the run.
set -euo pipefail
cd "$(dirname "$0")/.."
# -O1 -g1: the sanitizers' usual setting, much quicker to compile than -O2 -g and still fast
# enough to run the dataset tests; assertions stay on. A unity build, as scripts/build.sh's.
cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE="-O1 -g1" \
  -DCMAKE_C_FLAGS_RELEASE="-O1 -g1" -DTESSERA_SANITIZE=ON \
  -DCMAKE_UNITY_BUILD="${TESSERA_UNITY_BUILD:-ON}" > /dev/null
cmake --build build-asan -j "$(nproc)" --target tessera_unit_tests
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
# Without arguments every test but the [slow] ones: those (whole-dataset tracking, long rendered
# routes) run the same code as shorter tests under the sanitizers many times over and would take
# most of CI's time; the regular build runs them.
if [ $# -eq 0 ]; then set -- "~[slow]"; fi
build-asan/bin/tessera_unit_tests "$@"
