#!/usr/bin/env bash
# Refactor check: runs the same inputs through two `tessera` binaries and compares every output
# byte for byte (maps, trajectories, graphs, feature files) and summary.json without the figures
# that measure time or memory. Needs the datasets in ../shared/data.
#   bash scripts/compare_outputs.sh OLD_TESSERA NEW_TESSERA [WORK_DIR]
set -euo pipefail
old=$(realpath "$1"); new=$(realpath "$2")
work=${3:-$(mktemp -d /tmp/tessera_compare.XXXXXX)}
cd "$(dirname "$0")/.."
data=$(realpath ../shared/data)
# Option keys that differ between the two binaries (an option moved into a group): @NAME@ in a
# run stands for the old binary's key on the old side and the new binary's on the new side.
declare -A old_key=([seed]=slam.seed) new_key=([seed]=slam.rbpf.seed)
intel=(--set player.path=$data/intel-lab-mrpt/intel.clf.gz
       --set player.scan_times=$data/intel-lab-mrpt/frame_times.txt --set @seed@=1)
runs=(
  "sim_mapping|run sim_mapping"
  "carmen_rbpf|run carmen_rbpf ${intel[*]}"
  "carmen_global|run carmen_global ${intel[*]}"
  "sim_lines|run sim_lines"
  "sim_landmarks_rbekf|run sim_landmarks --set filter=rbekf"
  "sim_landmarks_ekf|run sim_landmarks --set filter=ekf"
  "urg_rbpf|run urg_rbpf --set player.path=$data/mines-paristech-urg04lx-odometry/exp2.dat.gz"
  "graph_m3500|graph optimize $data/posegraphs/M3500.g2o --json"
  "sim_slam_global|run sim_slam_global"
)
# summary.json figures that measure the machine, not the algorithm: times, memory, queue depths,
# and what keep-latest mailboxes dropped (intermediate optimised poses, say), which depends on
# thread timing and varies between two runs of the same binary.
strip_times() {  # FILE OUT_DIR: prints FILE's JSON without timings, OUT_DIR written as OUT
  python3 - "$1" "$2" <<'PY'
import json, re, sys
volatile = re.compile(r'(wall|cpu|rss|realtime|seconds|_s$|_ms$|_us|p50|p99|handler|time|rate|queue_depth|busy|drops|messages_in|optimized_pose_updates)')
def clean(v):
    if isinstance(v, dict):
        return {k: clean(x) for k, x in v.items() if not volatile.search(k)}
    if isinstance(v, list):
        return [clean(x) for x in v]
    if isinstance(v, str):
        return v.replace(sys.argv[2], 'OUT')
    return v
print(json.dumps(clean(json.load(open(sys.argv[1]))), indent=1, sort_keys=True))
PY
}
status=0
for entry in "${runs[@]}"; do
  name=${entry%%|*}
  for side in old new; do
    bin=$old; [ $side = new ] && bin=$new
    args=${entry#*|}
    for k in "${!old_key[@]}"; do
      if [ $side = old ]; then args=${args//@$k@/${old_key[$k]}}; else args=${args//@$k@/${new_key[$k]}}; fi
    done
    out=$work/$side/$name; rm -rf "$out"; mkdir -p "$out"
    if [[ $args == graph* ]]; then
      # shellcheck disable=SC2086
      $bin $args --out "$out/optimized.g2o" > "$out/stdout.json" 2> "$out/stderr.txt"
      strip_times "$out/stdout.json" "$out" > "$out/stdout.cmp"; rm "$out/stdout.json"
    else
      # shellcheck disable=SC2086
      $bin $args --out "$out" > "$out/stdout.txt" 2>&1 || { echo "[$name] $side run failed"; status=1; }
      rm -f "$out/stdout.txt"
      [ -f "$out/summary.json" ] && { strip_times "$out/summary.json" "$out" > "$out/summary.cmp"; rm "$out/summary.json"; }
    fi
  done
  if diff -r -q "$work/old/$name" "$work/new/$name" > "$work/$name.diff"; then
    echo "[$name] identical ($(ls "$work/new/$name" | wc -l) files)"
  else
    echo "[$name] DIFFERENT:"; sed 's/^/    /' "$work/$name.diff"; status=1
  fi
done
echo "outputs in $work"
exit $status
