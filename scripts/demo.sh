#!/usr/bin/env bash
# The main job on a built-in volume: set up, build, then load buckyball:129, build its
# hierarchy (cached on disk), and extract three transparent isosurfaces, triangles already in
# back-to-front order for the eye, to out/buckyball.ply and out/buckyball.glb.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh
VOLUME=${VOLUME:-buckyball:129}
ISO=${ISO:-0.05,0.15,0.25}
mkdir -p out
./build/server/isostream info --volume "$VOLUME"
./build/server/isostream extract --volume "$VOLUME" --iso "$ISO" --eps 0.01 \
  --eye 2.2,1.6,2.8 -o out/buckyball.ply --stats
./build/server/isostream extract --volume "$VOLUME" --iso "$ISO" --budget 200000 \
  --eye 2.2,1.6,2.8 -o out/buckyball.glb
