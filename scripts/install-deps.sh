#!/usr/bin/env bash
# Installs every Debian 12 package isostream needs to build, test and run.
# Idempotent: apt-get skips what is already there. Run as root or with sudo available.
# --tests: also what the tests alone need beyond Debian's packages, the npm packages of
# tests/interop (independent readers of the .glb output), with Node.js from apt if missing.
set -euo pipefail
cd "$(dirname "$0")/.."
tests=false
case "${1:-}" in
  --tests) tests=true ;;
  "") ;;
  *)
    echo "usage: install-deps.sh [--tests]" >&2
    exit 2
    ;;
esac

PACKAGES=(
  build-essential cmake pkg-config ccache git
  # volumes: OpenVDB's CMake config needs boost-iostreams, which libopenvdb-dev does not pull in
  libopenvdb-dev libboost-iostreams-dev libtbb-dev zlib1g-dev
  # mesh compression, ray queries, vector math
  libdraco-dev libembree-dev libglm-dev
  # headless GL through EGL on Mesa (llvmpipe needs no GPU and no X server)
  libegl-dev libgles-dev libegl-mesa0 libgl1-mesa-dri libgl-dev
  # libOpenGL.so, which CMake's OpenGL::OpenGL needs: nothing above pulls it in on a fresh system
  libopengl-dev
  # the viewer's --window mode (GLFW), and a virtual X server to test it headless
  libglfw3-dev xvfb xauth xdotool
  # transport
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  # the daemon checks that a TLS key belongs to its certificate (gRPC links OpenSSL already)
  libssl-dev
  # small well-kept libraries: CLI parsing, logging, JSON, PNG
  libcli11-dev libspdlog-dev libfmt-dev nlohmann-json3-dev libpng-dev libxxhash-dev libabsl-dev
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
  # the TLS tests' certificates (they skipped where a minimal image has no openssl)
  openssl
  # the systemd unit's check (tests/deploy): systemd-analyze, strace for the daemon's system calls
  systemd strace
)

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

# Node.js runs the interop test's readers. A machine may have it from elsewhere (NodeSource's
# packages, with their own npm): only a missing one is installed, Debian's.
if $tests && ! { command -v node && command -v npm; } > /dev/null 2>&1; then
  PACKAGES+=(nodejs npm)
fi

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
elif [ -n "$SUDO" ] && ! command -v sudo > /dev/null 2>&1; then
  echo "install-deps: not root and no sudo here: run this script as root, or install:" >&2
  echo "  ${missing[*]}" >&2
  exit 1
else
  echo "install-deps: installing ${missing[*]}"
  # Through env: sudo resets the environment, and a debconf question would wait for an answer.
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get update -q
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
    "${missing[@]}"
fi

# The interop test's packages, at the versions package-lock.json pins, into tests/interop (not
# the system). A stamp of the lock they were installed from skips the registry next time.
if $tests; then
  stamp=tests/interop/node_modules/.installed-from-lock
  if cmp -s tests/interop/package-lock.json "$stamp"; then
    echo "install-deps: tests/interop's npm packages present"
  else
    echo "install-deps: installing tests/interop's npm packages"
    npm ci --prefix tests/interop --no-audit --no-fund --loglevel=error
    cp tests/interop/package-lock.json "$stamp"
  fi
fi
