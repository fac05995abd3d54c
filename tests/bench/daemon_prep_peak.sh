#!/usr/bin/env bash
# isostreamd's peak resident memory while it prepares generated volumes asked for at once: one
# fetch per volume, all started together, against a daemon with the given --generator-mb (no
# cache, --max-dim 513). Prints the peak RSS (MB) and how many preparations waited for memory.
# Loopback only, one request per volume.
#   tests/bench/daemon_prep_peak.sh BUILD_DIR GENERATOR_MB VOLUME...
set -euo pipefail
cd "$(dirname "$0")/../.."
build=$1 budget=$2
shift 2
log=$(mktemp) out=$(mktemp -d)
"$build/server/isostreamd" --listen 127.0.0.1:0 --no-cache --generator-mb "$budget" \
  --max-dim 513 >"$log" 2>&1 &
daemon=$!
trap 'kill $daemon 2>/dev/null; wait $daemon 2>/dev/null; rm -rf "$log" "$out"' EXIT
for _ in $(seq 100); do grep -q "listening on" "$log" && break; sleep 0.1; done
address=$(grep -o "listening on [^ ]*" "$log" | head -1 | awk '{print $3}')
[ -n "$address" ] || { cat "$log"; exit 1; }
fetches=()
for v in "$@"; do
  "$build/server/isostream" fetch --server "$address" --volume "$v" --iso 0.3 --eps 0.05 \
    --eye 2,2,2 -o "$out/${v//:/_}.ply" >/dev/null 2>&1 &
  fetches+=($!)
done
for f in "${fetches[@]}"; do wait "$f" || { echo "a fetch failed"; exit 1; }; done
echo "generator-mb $budget, $*: peak $(awk '/VmHWM/ {printf "%.0f", $2 / 1024}' \
  "/proc/$daemon/status") MB, $(grep -c 'waits for memory' "$log" || true) waited for memory"
