#!/usr/bin/env bash
# ThreadSanitizer run of the runtime, shared-memory and actor tests (docs/architecture.md#runtime):
# a separate build in build-tsan/, then the unit tests of the runtime, messages and recording,
# the shared-memory transport's tests, and the actor and command tests (tessera_tests without its end-to-end runs of whole profiles,
# which run the same runtime code for minutes under a 5-15x slowdown). Any data race or lock-order
# inversion in our code fails the run; races inside libraries built without TSan (TBB's and
# iceoryx's own synchronisation, OpenCV's and zstd's thread pools) are suppressed in
# scripts/tsan.supp by library, never by our function names. Not part of .ci/run (its 45 min
# budget has no room for a third build); run it before touching the runtime or a threaded actor.
# Usage: scripts/tsan.sh [catch2 test spec for tessera_tests]
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE="-O1 -g1" \
  -DCMAKE_C_FLAGS_RELEASE="-O1 -g1" -DTESSERA_SANITIZE_THREAD=ON \
  -DCMAKE_UNITY_BUILD="${TESSERA_UNITY_BUILD:-ON}" > /dev/null
cmake --build build-tsan -j "$(nproc)" --target tessera_unit_tests tessera_tests tessera_shm_tests tessera
export TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 history_size=4 suppressions=$PWD/scripts/tsan.supp"
build-tsan/bin/tessera_unit_tests "[runtime],[recording],[messages]"
build-tsan/bin/tessera_shm_tests
if [ $# -eq 0 ]; then set -- "~[e2e]~[slow]"; fi
build-tsan/bin/tessera_tests "$@"
echo "[tsan] no data race reported"
