#!/usr/bin/env bash
# The main job on a built-in volume: set up, build, then load buckyball:129, build its
# hierarchy (cached), and extract three transparent isosurfaces in back-to-front order.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh
VOLUME=${VOLUME:-buckyball:129}
mkdir -p out
./build/server/isostream info --volume "$VOLUME"
