// Loading an OpenVDB file, and what the structure check (server/volume/vdb_structure.h) adds to
// it: dense N^3 float grids, written once per size into $TMPDIR (or /tmp) and kept there.
//   build/tests/bench/bench_load --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>
#include <openvdb/openvdb.h>
#include <sys/stat.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "server/volume/load.h"
#include "server/volume/vdb_structure.h"

namespace isostream {
namespace {

// A smooth dense field (every leaf present, values varied enough that Blosc keeps them long).
std::string DenseVdb(int n) {
  const char* tmp = std::getenv("TMPDIR");
  const std::string path =
      std::string(tmp ? tmp : "/tmp") + "/isostream_bench_dense_" + std::to_string(n) + ".vdb";
  struct stat st;
  if (stat(path.c_str(), &st) == 0) return path;
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setName("density");
  auto acc = grid->getAccessor();
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        acc.setValue(openvdb::Coord(i, j, k),
                     std::sin(i * 0.05f) * std::cos(j * 0.07f) + k * 0.001f);
  const std::string partial = path + ".partial";
  openvdb::io::File file(partial);
  file.write({grid});
  file.close();
  std::rename(partial.c_str(), path.c_str());
  return path;
}

void SetFileCounters(benchmark::State& state, const std::string& path) {
  struct stat st;
  stat(path.c_str(), &st);
  state.counters["file_MB"] = double(st.st_size) / 1e6;
}

void BM_CheckVdbStructure(benchmark::State& state) {
  const std::string path = DenseVdb(int(state.range(0)));
  openvdb::initialize();
  for (auto _ : state) {
    const absl::Status s = CheckVdbStructure(path);
    if (!s.ok()) state.SkipWithError(s.ToString().c_str());
  }
  SetFileCounters(state, path);
}

void BM_LoadVdb(benchmark::State& state) {
  const std::string path = DenseVdb(int(state.range(0)));
  for (auto _ : state) {
    absl::StatusOr<VolumePtr> v = LoadVolume(path);
    if (!v.ok()) state.SkipWithError(v.status().ToString().c_str());
    benchmark::DoNotOptimize(v);
  }
  SetFileCounters(state, path);
}

BENCHMARK(BM_CheckVdbStructure)->Arg(257)->Arg(513)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_LoadVdb)->Arg(257)->Arg(513)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace isostream

BENCHMARK_MAIN();
