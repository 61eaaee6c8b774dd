#!/usr/bin/env bash
# Installs (apt-get only) every system package Tessera needs to build, run and test.
# Idempotent: packages already present are skipped, so a second run costs a dpkg query.
set -euo pipefail

PACKAGES=(
  # toolchain
  build-essential cmake ninja-build ccache pkg-config git clang-format
  # design-card libraries
  libeigen3-dev libopencv-dev libpcl-dev liboctomap-dev libceres-dev libtbb-dev
  libopencv-contrib-dev  # rgbd::registerDepth (7-Scenes) and the odometries `bench rgbd` compares
  iceoryx libiceoryx-posh-dev libiceoryx-hoofs-dev libacl1-dev
  cyclonedds-dev cyclonedds-tools  # topics between hosts (ddsperf for reference figures)
  capnproto libcapnp-dev catch2
  # support libraries
  libyaml-cpp-dev nlohmann-json3-dev libcli11-dev libspdlog-dev libfmt-dev libzstd-dev zlib1g-dev libpng-dev libjpeg-dev
  libwebsocketpp-dev libasio-dev  # the live viewer's HTTP + WebSocket server (header-only)
  libfreenect-dev  # Kinect v1 driver (libfreenect0.5 also brings fakenect, its recording player)
  libsuitesparse-dev  # CHOLMOD for the Gauss-Newton pose-graph stage (Ceres pulls it in too)
  iproute2  # `ip netns`: the multi-host tests put each host in its own network namespace
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "[deps] all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "[deps] installing ${#missing[@]} missing packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
# No fsync per package (dpkg's unsafe I/O): a crash mid-install is not this script's concern, and
# it saves a good part of a fresh machine's install time.
$SUDO apt-get install -y -qq --no-install-recommends -o Dpkg::Options::=--force-unsafe-io \
  "${missing[@]}" >/dev/null
echo "[deps] done"
