#!/usr/bin/env bash
# The main job on a built-in volume: set up, build, start isostreamd on 127.0.0.1 (a free
# port), and let the thin client isostream-view render buckyball:129's three transparent
# isosurfaces, streamed already sorted back to front, to out/buckyball.png. Also writes the
# same frame with the CLI to out/buckyball.ply and out/buckyball.glb.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
BUILD_TARGETS="isostreamd isostream isostream-view" ./scripts/build.sh
BUILD_DIR=${BUILD_DIR:-build}  # as build.sh
VOLUME=${VOLUME:-buckyball:129}
ISO=${ISO:-0.05,0.15,0.25}
EYE=${EYE:-2.2,1.6,2.8}
mkdir -p out

"$BUILD_DIR"/server/isostream info --volume "$VOLUME"
"$BUILD_DIR"/server/isostream extract --volume "$VOLUME" --iso "$ISO" --eps 0.005 --eye "$EYE" \
  -o out/buckyball.ply --stats
"$BUILD_DIR"/server/isostream extract --volume "$VOLUME" --iso "$ISO" --budget 200000 --eye "$EYE" \
  -o out/buckyball.glb

log=$(mktemp)
"$BUILD_DIR"/server/isostreamd --listen 127.0.0.1:0 > "$log" 2>&1 &
daemon=$!
trap 'kill "$daemon" 2>/dev/null || true; wait "$daemon" 2>/dev/null || true; rm -f "$log"' EXIT
for _ in $(seq 100); do
  grep -q "listening on" "$log" && break
  kill -0 "$daemon" 2>/dev/null || break  # it exited: say why below, not after 10 s
  sleep 0.1
done
# No match must reach the message below, not end the script silently (set -e).
port=$(grep -m1 -oE "listening on [0-9.]+:[0-9]+" "$log" | sed 's/.*://' || true)
[ -n "$port" ] || { cat "$log"; echo "isostreamd did not start"; exit 1; }
echo "isostreamd on 127.0.0.1:$port"
# A failure the server explains in its log (not to the client) is shown before the log goes.
"$BUILD_DIR"/client/view/isostream-view --server "127.0.0.1:$port" --volume "$VOLUME" --iso "$ISO" \
  --eps 0.005 --eye "$EYE" --size 800x800 -o out/buckyball.png \
  || { echo "isostream-view failed; isostreamd's log:"; cat "$log"; exit 1; }
echo "wrote out/buckyball.png"
