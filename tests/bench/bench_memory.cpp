// What one random cache line costs on this machine, the ceiling under extraction from a large
// hierarchy: the 513^3 frames touch millions of scattered lines of an 840 MB store.
//   build/tests/bench/bench_memory --benchmark_counters_tabular=true
// Column ns_per_line. BM_DependentLine: each load's address comes from the previous one (pure
// latency), over a span from L2-sized to the size of a 513^3 hierarchy. BM_IndependentLines:
// independent random lines with a software prefetch `distance` loads ahead (0: none), i.e. how
// many lines per second the memory system delivers when the code exposes the parallelism.
#include <benchmark/benchmark.h>
#include <sys/mman.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <numeric>
#include <random>
#include <vector>

namespace {

constexpr size_t kLine = 64;
constexpr size_t kHuge = size_t{2} << 20;

// One store for every case, as large as a 513^3 hierarchy, on huge pages like the bricks, and
// touched once so no case pays its page faults.
char* Store(size_t* bytes) {
  static const size_t size = size_t{840} << 20;
  static char* store = [] {
    char* p = static_cast<char*>(std::aligned_alloc(kHuge, size));
    madvise(p, size, MADV_HUGEPAGE);
    for (size_t i = 0; i < size; i += 4096) p[i] = 1;
    return p;
  }();
  *bytes = size;
  return store;
}

// Runs body() once per iteration; returns nanoseconds per load.
template <typename Body>
double TimeLoads(benchmark::State& state, size_t loads_per_iteration, Body body) {
  double ns = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    body();
    ns += std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
  }
  return ns / (double(loads_per_iteration) * double(state.iterations()));
}

void BM_DependentLine(benchmark::State& state) {
  size_t size;
  char* store = Store(&size);
  const size_t span = std::min(size, size_t(state.range(0)) << 20);
  const size_t lines = span / kLine, cycle = std::min<size_t>(lines, 1 << 20);
  // A random cycle through `cycle` lines of the span: every load misses what the last one
  // brought in, and the next address is known only when it arrives.
  std::vector<size_t> order(lines);
  std::iota(order.begin(), order.end(), size_t{0});
  std::shuffle(order.begin(), order.end(), std::mt19937_64(1));
  for (size_t i = 0; i < cycle; ++i)
    *reinterpret_cast<char**>(store + order[i] * kLine) = store + order[(i + 1) % cycle] * kLine;
  char* p = store + order[0] * kLine;
  constexpr int kHops = 1 << 16;
  state.counters["ns_per_line"] = TimeLoads(state, kHops, [&] {
    for (int i = 0; i < kHops; ++i) p = *reinterpret_cast<char**>(p);
    benchmark::DoNotOptimize(p);
  });
}

void BM_IndependentLines(benchmark::State& state) {
  size_t size;
  char* store = Store(&size);
  const int distance = int(state.range(0));
  constexpr size_t kLoads = size_t{1} << 22;  // 256 MB of distinct lines per pass: no reuse
  std::vector<size_t> offsets(kLoads + 64);
  std::mt19937_64 rng(2);
  for (auto& o : offsets) o = (rng() % (size / kLine)) * kLine;
  int64_t sum = 0;
  state.counters["ns_per_line"] = TimeLoads(state, kLoads, [&] {
    for (size_t i = 0; i < kLoads; ++i) {
      if (distance > 0) __builtin_prefetch(store + offsets[i + distance]);
      sum += store[offsets[i]];
    }
    benchmark::DoNotOptimize(sum);
  });
}

BENCHMARK(BM_DependentLine)->Arg(1)->Arg(16)->Arg(64)->Arg(256)->Arg(840)->MinTime(0.3);
BENCHMARK(BM_IndependentLines)->Arg(0)->Arg(8)->Arg(16)->Arg(32)->Arg(64)->MinTime(0.3);

}  // namespace

BENCHMARK_MAIN();
