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

# A NIfTI file in millimetres (xyzt_units 2): the node scales to glTF's meters, and the
# validator must accept the document with that scale (the vertices stay in millimetres, as
# the PLY's).
node -e '
const n = 17, c = (n - 1) / 2, h = Buffer.alloc(352), d = Buffer.alloc(4 * n * n * n);
h.writeInt32LE(348, 0);
[3, n, n, n, 1, 1, 1, 1].forEach((v, i) => h.writeInt16LE(v, 40 + 2 * i));
h.writeInt16LE(16, 70); h.writeInt16LE(32, 72);  // float32
[1, 0.5, 0.5, 0.5, 1, 1, 1, 1].forEach((v, i) => h.writeFloatLE(v, 76 + 4 * i));
h.writeFloatLE(352, 108);
h[123] = 2;  // NIFTI_UNITS_MM
h.write("n+1\0", 344, "latin1");
for (let z = 0, i = 0; z < n; ++z)
  for (let y = 0; y < n; ++y)
    for (let x = 0; x < n; ++x, ++i) d.writeFloatLE(Math.hypot(x - c, y - c, z - c), 4 * i);
require("fs").writeFileSync(process.argv[1], Buffer.concat([h, d]));
' "$work/mm.nii"
check millimetres "$work/mm.nii" 5 0 20,15,25
node -e '
const b = require("fs").readFileSync(process.argv[1]);
const doc = JSON.parse(b.subarray(20, 20 + b.readUInt32LE(12)).toString());
const s = JSON.stringify(doc.nodes[0].scale);
if (s !== "[0.001,0.001,0.001]") { console.error(`check_glb: node scale ${s}`); process.exit(1); }
console.log("check_glb: node scale", s);
' "$work/millimetres.glb"
