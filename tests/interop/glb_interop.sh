#!/usr/bin/env bash
# The CLI's .glb output read by readers that share no code with isostream (check_glb.mjs:
# Khronos's glTF validator, glTF-Transform with Google's Draco decoder) and compared, triangle
# by triangle in draw order, with the PLY of the same extraction.
# Usage: glb_interop.sh PATH/TO/isostream
set -euo pipefail
cli=$1
here=$(cd "$(dirname "$0")" && pwd)
# Skipped (77, ctest's SKIP_RETURN_CODE) without them, as after the demo's set-up; the README's
# test command installs them, and fails itself if it cannot.
if ! command -v node > /dev/null || [ ! -f "$here/node_modules/draco3dgltf/package.json" ]; then
  echo "glb_interop: skipped: needs Node.js and this folder's npm packages:" \
    "run scripts/install-deps.sh --tests" >&2
  exit 77
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
export ISOSTREAM_CACHE_DIR="$work/cache"

# check NAME VOLUME ISOVALUES EPS EYE
check() {
  local name=$1 args=(--volume "$2" --iso "$3" --eps "$4" --eye "$5")
  local out
  for out in "$work/$name.glb" "$work/$name.ply"; do
    "$cli" extract "${args[@]}" -o "$out" > "$work/log" 2>&1 || { cat "$work/log" >&2; exit 1; }
  done
  # Positions are quantized for 1/64 of the finest sample step: allow that step.
  local tolerance
  tolerance=$("$cli" info --volume "$2" |
    awk '$1 == "spacing" { m = $2; if ($3 < m) m = $3; if ($4 < m) m = $4; print m / 64 }')
  echo "$name ($2, iso $3, eps $4, eye $5):"
  node "$here/check_glb.mjs" "$work/$name.glb" "$work/$name.ply" "$tolerance"
}

check surfaces buckyball:65 0.05,0.15,0.25 0.005 2.5,1.8,3.1  # three surfaces, their colours
check wide cayley:129 0 0 -2.5,1.8,3.1                        # over 65,535 vertices
check clipped cayley:100 -0.5,0.5 0.002 0.1,0.2,0.3           # padded volume, eye inside
check empty cayley:65 100 0 2.5,1.8,3.1                       # no surface: an empty scene
