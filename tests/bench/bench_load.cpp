// Loading an OpenVDB file, and what the structure check (server/volume/vdb_structure.h) adds to
// it: dense N^3 float grids, written once per size into $TMPDIR (or /tmp) and kept there. And
// loading a NIfTI file stored as the world's axes or turned (orientation.h: x reversed, y and z
// swapped), to show what the rebuild along the world's axes costs.
//   build/tests/bench/bench_load --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>
#include <openvdb/openvdb.h>
#include <sys/stat.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

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

// A float32 N^3 NIfTI file whose sform is the identity, or (turned) puts file axis i on world
// -x, j on +z and k on +y.
std::string DenseNifti(int n, bool turned) {
  const char* tmp = std::getenv("TMPDIR");
  const std::string path = std::string(tmp ? tmp : "/tmp") + "/isostream_bench_dense_" +
                           std::to_string(n) + (turned ? "_turned" : "") + ".nii";
  struct stat st;
  if (stat(path.c_str(), &st) == 0) return path;
  std::vector<char> header(352, 0);
  auto put = [&](int offset, auto value) { std::memcpy(&header[offset], &value, sizeof(value)); };
  put(0, int32_t{348});
  put(40, int16_t{3});
  for (int a = 0; a < 3; ++a) put(42 + 2 * a, int16_t(n));
  put(70, int16_t{16});  // float32
  put(72, int16_t{32});
  for (int a = 0; a < 4; ++a) put(76 + 4 * a, 1.0f);
  put(108, 352.0f);
  put(254, int16_t{1});  // sform_code
  const float identity[3][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}};
  const float swapped[3][4] = {{-1, 0, 0, float(n - 1)}, {0, 0, 1, 0}, {0, 1, 0, 0}};
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) put(280 + 16 * r + 4 * c, (turned ? swapped : identity)[r][c]);
  std::memcpy(&header[344], "n+1", 4);
  const std::string partial = path + ".partial";
  std::ofstream out(partial, std::ios::binary);
  out.write(header.data(), std::streamsize(header.size()));
  std::vector<float> row(size_t(n) * n);
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        row[size_t(j) * n + i] = std::sin(i * 0.05f) * std::cos(j * 0.07f) + k * 0.001f;
    out.write(reinterpret_cast<const char*>(row.data()), std::streamsize(row.size() * 4));
  }
  out.close();
  if (!out) return "";  // a short file (a full disk) is not kept for later runs
  std::rename(partial.c_str(), path.c_str());
  return path;
}

void BM_LoadNifti(benchmark::State& state) {
  const std::string path = DenseNifti(int(state.range(0)), state.range(1) != 0);
  if (path.empty()) return state.SkipWithError("cannot write the NIfTI file");
  for (auto _ : state) {
    absl::StatusOr<VolumePtr> v = LoadVolume(path);
    if (!v.ok()) state.SkipWithError(v.status().ToString().c_str());
    benchmark::DoNotOptimize(v);
  }
  SetFileCounters(state, path);
}

BENCHMARK(BM_CheckVdbStructure)->Arg(257)->Arg(513)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_LoadVdb)->Arg(257)->Arg(513)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_LoadNifti)
    ->ArgNames({"n", "turned"})
    ->ArgsProduct({{257, 513}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace isostream

BENCHMARK_MAIN();
