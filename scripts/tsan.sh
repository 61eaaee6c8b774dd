#!/usr/bin/env bash
# ThreadSanitizer run (docs/architecture.md#runtime): a separate build in build-tsan/, then the
# unit tests of the runtime, messages and recording, the shared-memory transport's tests and,
# on request, actor and command tests. Races inside libraries built without TSan (TBB's,
# iceoryx's, OpenCV's and zstd's own synchronisation) are suppressed in scripts/tsan.supp by
# library or by their template namespaces, never by our function names. Not part of .ci/run
# (its 45 min budget has no room for a third build); run it before touching the runtime.
# Usage: scripts/tsan.sh [catch2 test spec for tessera_tests]
# Last run (2026-12-05): the runtime, recording and message unit tests clean after it found one
# real race, fixed (the runtime's `started` flag, read by the shared-memory receive thread).
# The launch tests in tessera_shm_tests run whole profiles whose RBPF uses TBB's parallel_for,
# and TBB's task handoffs (Debian's libtbb is not built with TSan) still show up as races in
# the particles' grids there.
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE="-O1 -g1" \
  -DCMAKE_C_FLAGS_RELEASE="-O1 -g1" -DTESSERA_SANITIZE_THREAD=ON \
  -DCMAKE_UNITY_BUILD="${TESSERA_UNITY_BUILD:-ON}" > /dev/null
cmake --build build-tsan -j "$(nproc)" --target tessera_unit_tests tessera_tests tessera_shm_tests tessera
# report_mutex_bugs=0: iceoryx locks its process-shared mutexes in the library and unlocks some
# in header code compiled into ours; TSan sees only the unlock (our mutexes are std::mutex and
# still checked for races and lock-order inversions).
export TSAN_OPTIONS="halt_on_error=1 report_mutex_bugs=0 second_deadlock_stack=1 history_size=4 suppressions=$PWD/scripts/tsan.supp"
build-tsan/bin/tessera_unit_tests "[runtime],[recording],[messages]"
build-tsan/bin/tessera_shm_tests
# Actor and command tests only on request (a Catch2 spec, e.g. "[visual_slam]"): actors that
# run TBB's parallel_for (the RBPF's particles, the matchers) report TBB's own task handoffs as
# races, since Debian's libtbb is not built with TSan (docs/architecture.md#runtime).
if [ $# -gt 0 ]; then build-tsan/bin/tessera_tests "$@"; fi
echo "[tsan] no data race reported"
