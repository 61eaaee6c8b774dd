#!/usr/bin/env bash
# Builds oneTBB with ThreadSanitizer for scripts/tsan.sh (docs/architecture.md#runtime).
# Debian's libtbb is not instrumented, so TSan cannot see TBB's own synchronisation and reports
# every parallel_for handoff as a race. This takes the very version Debian 12 ships (source
# package onetbb 2021.8.0-2+deb12u1: the upstream tarball plus Debian's patches, both checked
# against the .dsc's SHA-256), builds it with TBB_SANITIZE=thread and installs it under
# build-tsan/tbb/. scripts/tsan.sh then compiles against its headers and runs with its
# libraries first on the search path. The result is cached: the script does nothing when
# build-tsan/tbb/ already holds this version.
# Usage: scripts/tsan_tbb.sh   (needs network access to deb.debian.org, a few minutes on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
version=2021.8.0
debian_revision=2+deb12u1
orig_sha256=7e9111b8bb59c8800bf6d0b06afe7b0891937443d2dae1ee1101c8e2ede6a7ef
debian_sha256=b83a270205b38cdf66972fa1467c3e29493b88b92ecacf4f3672e87d67199df5
pool=${DEBIAN_MIRROR:-http://deb.debian.org/debian}/pool/main/o/onetbb
prefix=$PWD/build-tsan/tbb
stamp=$prefix/.tessera-tsan-$version-$debian_revision
if [ -f "$stamp" ]; then
  echo "[tsan-tbb] $prefix already holds oneTBB $version-$debian_revision with TSan"
  exit 0
fi
work=$PWD/build-tsan/tbb-src
rm -rf "$work" && mkdir -p "$work"
fetch() { # file sha256
  echo "[tsan-tbb] fetching $pool/$1"
  curl -fsSL --retry 3 -o "$work/$1" "$pool/$1"
  if ! echo "$2  $work/$1" | sha256sum -c --quiet; then
    echo "[tsan-tbb] $1: SHA-256 does not match Debian's .dsc ($2)" >&2
    exit 1
  fi
}
fetch "onetbb_$version.orig.tar.xz" "$orig_sha256"
fetch "onetbb_$version-$debian_revision.debian.tar.xz" "$debian_sha256"
tar -C "$work" -xf "$work/onetbb_$version.orig.tar.xz"
src=$(find "$work" -mindepth 1 -maxdepth 1 -type d | head -n 1)
tar -C "$src" -xf "$work/onetbb_$version-$debian_revision.debian.tar.xz"
if [ -f "$src/debian/patches/series" ]; then
  grep -v '^\s*#' "$src/debian/patches/series" | while read -r p; do
    [ -n "$p" ] && patch -d "$src" -p1 -s < "$src/debian/patches/$p"
  done
fi
# Tests and examples off (they take most of the build time); -O1 -g1 as in build-tsan.
cmake -S "$src" -B "$work/build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g1" \
  -DTBB_SANITIZE=thread -DTBB_TEST=OFF -DTBB_EXAMPLES=OFF -DTBB_STRICT=OFF \
  -DTBB4PY_BUILD=OFF -DCMAKE_INSTALL_PREFIX="$prefix" -DCMAKE_INSTALL_LIBDIR=lib > /dev/null
cmake --build "$work/build" -j "$(nproc)"
cmake --install "$work/build" > /dev/null
touch "$stamp"
rm -rf "$work"
echo "[tsan-tbb] oneTBB $version-$debian_revision with TSan installed in $prefix"
