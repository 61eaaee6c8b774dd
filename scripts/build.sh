#!/usr/bin/env bash
# Configures and builds Tessera into build/ (Release, Ninja, ccache when present).
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=$(nproc)
# A fresh tree is configured as a unity build (cmake/TesseraTargets.cmake): the heavy headers
# (Eigen, OpenCV, Catch2) are parsed once per batch of files instead of once per file, which
# makes a cold build much quicker (docs/benchmarks.md#build-and-tests-bash-cirun). For editing and
# rebuilding, TESSERA_UNITY_BUILD=OFF (or any tree configured without it) recompiles one file.
if [ ! -f build/CMakeCache.txt ]; then
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_UNITY_BUILD="${TESSERA_UNITY_BUILD:-ON}"
fi
cmake --build build -j "$jobs"
