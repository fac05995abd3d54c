#!/usr/bin/env bash
# Runs the benchmark programs whose figures BENCHMARKS.md records (the daemon's memory scripts,
# tests/bench/daemon_*.sh, start daemons of their own and are run by hand). Run on an otherwise
# idle machine.
#   ./scripts/bench.sh [build-dir]
set -euo pipefail
cd "$(dirname "$0")/.."
B=${1:-build}
"$B/tests/bench/bench_load" --benchmark_counters_tabular=true
"$B/tests/bench/bench_hierarchy" --benchmark_counters_tabular=true
"$B/tests/bench/bench_extract" --benchmark_counters_tabular=true
"$B/tests/bench/bench_memory" --benchmark_counters_tabular=true
"$B/tests/bench/bench_stream"
"$B/client/bench_render" --benchmark_counters_tabular=true
for args in "cayley:65 0 0" "cayley:65 0.05 -0.5 0 0.5" "buckyball:65 0 0.05 0.15 0.25" \
            "buckyball:65 0.01 0.05 0.15 0.25"; do
  # shellcheck disable=SC2086
  "$B/tests/bench/bench_culling" $args
done
