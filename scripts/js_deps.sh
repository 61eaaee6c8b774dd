#!/usr/bin/env bash
# Installs the npm packages tests read Tessera's outputs with (tests/js: @mcap/core, fzstd and
# playwright-core, exactly as package-lock.json pins them), and Debian's nodejs + npm first when the machine has
# no npm (a machine with its own Node.js, e.g. NodeSource's, keeps it). Only the tests need
# them: the demo never runs this. When npm cannot be had, the checks that need it are skipped,
# except under CI=true, where that is a failure.
set -euo pipefail
cd "$(dirname "$0")/../tests/js"
if ! command -v npm > /dev/null; then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  echo "[js] installing Debian's nodejs and npm"
  if ! { DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
           nodejs npm > /dev/null; } || ! command -v npm > /dev/null; then
    if [ "${CI:-}" = true ]; then
      echo "[js] npm is missing and could not be installed" >&2
      exit 1
    fi
    echo "[js] no npm: the tests that read MCAP files with @mcap/core will be skipped"
    exit 0
  fi
fi
# Debian's Chromium for the live viewer's browser test (tests/js/viewer_e2e.mjs, playwright-core
# drives it headless); installed under CI or when this script may use apt-get as root.
if [ ! -x /usr/bin/chromium ] && { [ "${CI:-}" = true ] || [ "$(id -u)" -eq 0 ]; }; then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  echo "[js] installing Debian's chromium (headless browser for the viewer test)"
  install_chromium() {
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
      -o Dpkg::Options::=--force-unsafe-io chromium > /dev/null
  }
  # Stale package lists (a machine whose other packages were all present) get one refresh.
  if ! install_chromium && ! { $SUDO apt-get update -qq && install_chromium; }; then
    if [ "${CI:-}" = true ]; then
      echo "[js] chromium could not be installed" >&2
      exit 1
    fi
    echo "[js] no chromium: the viewer's browser test will be skipped"
  fi
fi
if [ -f node_modules/.package-lock.json ] && [ node_modules/.package-lock.json -nt package-lock.json ]; then
  echo "[js] packages present"
  exit 0
fi
npm ci --no-audit --no-fund --loglevel=error
echo "[js] packages installed"
