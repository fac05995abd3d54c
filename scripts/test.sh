#!/usr/bin/env bash
# Sets up a fresh Debian 12 machine, builds, and runs every test (unit and integration).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh
cd "${BUILD_DIR:-build}"  # as build.sh
ctest --output-on-failure -j"$(nproc 2>/dev/null || echo 2)" --timeout 600
