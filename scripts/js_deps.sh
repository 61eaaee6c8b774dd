#!/usr/bin/env bash
# Installs the npm packages tests read Tessera's outputs with (tests/js: @mcap/core and fzstd,
# exactly as package-lock.json pins them). Without npm the checks that need them are skipped,
# except under CI=true, where that is a failure.
set -euo pipefail
cd "$(dirname "$0")/../tests/js"
if ! command -v npm > /dev/null; then
  if [ "${CI:-}" = true ]; then
    echo "[js] npm is missing (scripts/install_deps.sh installs it)" >&2
    exit 1
  fi
  echo "[js] no npm: the tests that read MCAP files with @mcap/core will be skipped"
  exit 0
fi
if [ -f node_modules/.package-lock.json ] && [ node_modules/.package-lock.json -nt package-lock.json ]; then
  echo "[js] packages present"
  exit 0
fi
npm ci --no-audit --no-fund --loglevel=error
echo "[js] packages installed"
