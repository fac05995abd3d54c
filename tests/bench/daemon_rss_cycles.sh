#!/usr/bin/env bash
# isostreamd's resident memory over prepare/evict cycles: three generated 257^3 volumes taken
# in turn under a generator budget that holds one, so every request prepares a volume and drops
# another. Prints the cycle, the volume, RSS and peak RSS (MB). Loopback only, bounded in count.
#   tests/bench/daemon_rss_cycles.sh [BUILD_DIR=build] [CYCLES=24] [GENERATOR_MB=150]
set -euo pipefail
cd "$(dirname "$0")/../.."
build=${1:-build} cycles=${2:-24} budget=${3:-150}
log=$(mktemp) out=$(mktemp --suffix=.ply)
scratch=$out
source tests/bench/daemon_bench_start.sh
start_daemon --no-cache --generator-mb "$budget"
volumes=(cayley:257 buckyball:257 noise:257)
mb() { awk -v k="$1" '$1 == k":" {printf "%.0f", $2 / 1024}' "/proc/$daemon/status"; }
for i in $(seq "$cycles"); do
  v=${volumes[$((i % 3))]}
  if ! said=$("$build/server/isostream" fetch --server "$address" --volume "$v" --iso 0.1 \
    --eps 0.01 --eye 2.5,1.8,3.1 -o "$out" 2>&1); then
    echo "$said"
    exit 1
  fi
  echo "$i $v rss $(mb VmRSS) MB peak $(mb VmHWM) MB"
done
