#!/usr/bin/env bash
# ThreadSanitizer run (docs/architecture.md#runtime): a separate build in build-tsan/, against a
# oneTBB built with TSan from Debian's own source package (scripts/tsan_tbb.sh), so TBB's task
# handoffs are seen for what they are. Then the unit tests of the runtime, messages and
# recording, the shared-memory transport's tests (whole profiles launched as processes), and the
# actor and command tests. Races inside libraries built without TSan (iceoryx's, OpenCV's and
# zstd's own synchronisation) are suppressed in scripts/tsan.supp by library, never by our
# function names. Not part of .ci/run (its 45 min budget has no room for a third build); run it
# before touching the runtime or an actor's threads.
# Usage: scripts/tsan.sh [catch2 test spec for tessera_tests; default: all of it]
# The last clean run is logged in docs/benchmarks.md#build-and-tests.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/tsan_tbb.sh
cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS_RELEASE="-O1 -g1" \
  -DCMAKE_C_FLAGS_RELEASE="-O1 -g1" -DTESSERA_SANITIZE_THREAD=ON \
  -DTBB_DIR="$PWD/build-tsan/tbb/lib/cmake/TBB" \
  -DCMAKE_UNITY_BUILD="${TESSERA_UNITY_BUILD:-ON}" > /dev/null
cmake --build build-tsan -j "$(nproc)" --target tessera_unit_tests tessera_tests tessera_shm_tests tessera
export LD_LIBRARY_PATH="$PWD/build-tsan/tbb/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
if ! ldd build-tsan/bin/tessera_tests | grep -q "build-tsan/tbb/lib/libtbb.so"; then
  echo "[tsan] build-tsan/bin/tessera_tests does not load the TSan oneTBB of build-tsan/tbb" >&2
  exit 1
fi
# report_mutex_bugs=0: iceoryx locks its process-shared mutexes in the library and unlocks some
# in header code compiled into ours; TSan sees only the unlock (our mutexes are std::mutex and
# still checked for races and lock-order inversions).
export TSAN_OPTIONS="halt_on_error=1 report_mutex_bugs=0 second_deadlock_stack=1 history_size=4 suppressions=$PWD/scripts/tsan.supp"
build-tsan/bin/tessera_unit_tests "[runtime],[recording],[messages]"
# Without the two whole-SLAM launches ([slow]: minutes each under TSan, on the code paths the
# shorter launches cover).
build-tsan/bin/tessera_shm_tests "~[slow]"
# The actors that run threads or TBB inside (particles, features, matching, rebuilds, servers,
# device loops) and the profiles that run them, in process and as `tessera run`. Without the
# soak benchmarks, [slow] cases (TSan runs 5-15x slower; they add nothing the others miss) and
# [wall_clock] ones (they check timing against the wall clock, which TSan stretches), and the
# emulated Kinect robot, whose tracker takes the frames as they come on the wall clock
# (keep_latest): slowed down 10x it skips most of them, and its check counts them.
if [ $# -gt 0 ]; then
  spec="$1"
else
  spec=""
  for tag in actor actors rbpf localization map_merger visual_slam mapping3d rgbd_mapper viewer \
    drivers lifelong loop_detector submap_builder graph_optimizer navigator; do
    spec="${spec:+$spec,}[$tag]~[slow]~[bench_soak]~[wall_clock]~\"robot_create_kinect*\""
  done
fi
# One process per test case, as ctest runs them (the Kinect cases load different libfreenects).
failed=()
while IFS= read -r name; do
  [ -n "$name" ] || continue
  escaped=$(printf '%s' "$name" | sed 's/[],[\\]/\\&/g')
  if ! build-tsan/bin/tessera_tests "$escaped" > build-tsan/tsan_case.log 2>&1; then
    failed+=("$name")
    cat build-tsan/tsan_case.log
  fi
done < <(build-tsan/bin/tessera_tests --list-test-names-only "$spec")
if [ ${#failed[@]} -gt 0 ]; then
  printf '[tsan] failed: %s\n' "${failed[@]}" >&2
  exit 1
fi
echo "[tsan] no data race reported"
