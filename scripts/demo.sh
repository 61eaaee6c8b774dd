#!/usr/bin/env bash
# The README's first command: install dependencies, build, and map the built-in simulated office.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
out=${1:-out/sim_mapping}
./build/bin/tessera run sim_mapping --out "$out"
