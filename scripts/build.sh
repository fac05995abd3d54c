#!/usr/bin/env bash
# Configures and builds isostream (Release) into build/ (BUILD_DIR). Used by demo.sh and
# test.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release "$@" > "$BUILD_DIR.configure.log" 2>&1 \
  || { cat "$BUILD_DIR.configure.log"; exit 1; }
# BUILD_TARGETS (space separated) builds only those, with what they need: the demo needs three
# programs, not the tests and benchmarks (most of a cold build).
# shellcheck disable=SC2086
cmake --build "$BUILD_DIR" -j"$jobs" ${BUILD_TARGETS:+--target $BUILD_TARGETS}
