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
scratch=$out
source tests/bench/daemon_bench_start.sh
start_daemon --no-cache --generator-mb "$budget" --max-dim 513
fetches=()
for v in "$@"; do
  "$build/server/isostream" fetch --server "$address" --volume "$v" --iso 0.3 --eps 0.05 \
    --eye 2,2,2 -o "$out/${v//:/_}.ply" >/dev/null 2>&1 &
  fetches+=($!)
done
for f in "${fetches[@]}"; do wait "$f" || { echo "a fetch failed"; exit 1; }; done
echo "generator-mb $budget, $*: peak $(awk '/VmHWM/ {printf "%.0f", $2 / 1024}' \
  "/proc/$daemon/status") MB, $(grep -c 'waits for memory' "$log" || true) waited for memory"
