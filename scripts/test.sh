#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine, builds, and runs every test (unit and integration).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh --tests
# Tests on, whatever an earlier configure of this build directory chose.
./scripts/build.sh -DISOSTREAM_BUILD_TESTS=ON
cd "${BUILD_DIR:-build}"  # as build.sh
# No tests found is a failure, not a pass.
ctest --output-on-failure --no-tests=error -j"$(nproc 2>/dev/null || echo 2)" --timeout 600
