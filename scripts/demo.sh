#!/usr/bin/env bash
# The README's first command: install dependencies, build, and run the flagship, two-level laser
# SLAM (RBPF submaps, loop closure, pose-graph optimisation) on the built-in simulated office;
# then print its accuracy against the simulator's ground truth, the loop closures it found, and
# where the map and the other outputs are.
#   bash scripts/demo.sh [OUT_DIR]      (default out/demo)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
out=${1:-out/demo}
tessera=./build/bin/tessera
$tessera run sim_slam_global --out "$out"

rmse() {  # ATE RMSE [m] of one trajectory against ground truth (SE(2) alignment)
  $tessera eval ate --estimate "$out/$1" --reference "$out/ground_truth.tum" --json 2>/dev/null |
    sed -n 's/.*"rmse_m": *\([0-9.eE+-]*\).*/\1/p' | xargs printf '%.3f m'
}
figure() {  # one number from summary.json
  sed -n "s/.*\"$1\": *\([0-9.]*\).*/\1/p" "$out/summary.json" | head -n 1
}
cat <<REPORT

== Tessera demo: two-level laser SLAM on the simulated office ==
Accuracy against ground truth (ATE RMSE, SE(2) alignment; tessera eval ate):
  wheel odometry               odometry.tum          $(rmse odometry.tum)
  online estimate              trajectory.tum        $(rmse trajectory.tum)
  after loop closure + graph   trajectory_final.tum  $(rmse trajectory_final.tum)
Submaps: $(figure submaps); loop closures accepted: $(figure loops_accepted) ($(figure loops_true) true, $(figure loops_false) false against ground truth)
Map: $out/map.yaml + map.pgm (ROS map_server / rviz), $out/map.png
Trajectories (TUM, open with evo: evo_traj tum $out/trajectory_final.tum --ref $out/ground_truth.tum -p)
Submap pose graph: $out/graph.g2o (g2o_viewer; tessera graph optimize)
Figures of the run: $out/summary.json
REPORT
