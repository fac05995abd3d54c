// Extraction speed: sorted (back-to-front) vs --order none, 1 vs 2 threads, blocks vs node by
// node for the last three levels, the budget search (first view of a budget), an
// extract-then-sort baseline (same traversal unsorted, then std::sort by centroid depth), and
// the view change served from a retained cut (what recording it costs, and re-ordering it).
//   build/tests/bench/bench_extract --benchmark_counters_tabular=true
// Cases: cayley:513 iso 0 and -0.5,0,0.5; buckyball:513 iso .05,.15,.25, each at the eps that
// gives about 1 M triangles; cayley:257 iso 0 at eps = 0.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <map>
#include <numeric>

#include "server/extract/extractor.h"
#include "server/extract/retained_cut.h"
#include "server/hierarchy/hierarchy.h"
#include "server/volume/load.h"
#include "server/volume/padding.h"
#include "shared/malloc_tuning.h"

namespace isostream {
namespace {

struct Scene {
  HierarchyPtr hierarchy;
  GridToWorld xf;
  ExtractRequest request;  // eps already resolved
};

struct CaseSpec {
  const char* volume;
  std::vector<float> iso;
  int64_t target_triangles;  // 0: use eps = 0
};

const std::vector<CaseSpec>& Cases() {
  static const std::vector<CaseSpec> cases = {
      {"cayley:513", {0.0f}, 1000000},
      {"cayley:513", {-0.5f, 0.0f, 0.5f}, 1000000},
      {"buckyball:513", {0.05f, 0.15f, 0.25f}, 1000000},
      {"cayley:257", {0.0f}, 0},
  };
  return cases;
}

const Scene& GetScene(int index) {
  static std::map<int, Scene> scenes;
  static std::map<std::string, std::pair<HierarchyPtr, GridToWorld>> volumes;
  auto it = scenes.find(index);
  if (it != scenes.end()) return it->second;
  const CaseSpec& spec = Cases()[index];
  auto& vol = volumes[spec.volume];
  if (!vol.first) {
    auto volume = LoadVolume(spec.volume);
    auto padded = PadToHierarchyDomain(**volume);
    vol.first = *BuildHierarchy(std::move(*padded));
    for (int a = 0; a < 3; ++a) {
      vol.second.origin[a] = (*volume)->origin[a];
      vol.second.spacing[a] = (*volume)->spacing[a];
    }
  }
  Scene s;
  s.hierarchy = vol.first;
  s.xf = vol.second;
  s.request.isovalues = spec.iso;
  s.request.view.eye = {2.5, 1.8, 3.1};  // outside [-1,1]^3, an oblique view
  if (spec.target_triangles > 0) {
    ExtractRequest probe = s.request;
    probe.budget = spec.target_triangles;
    s.request.eps = Extract(*s.hierarchy, s.xf, probe)->stats.eps_used;
  }
  return scenes.emplace(index, std::move(s)).first->second;
}

void Report(benchmark::State& state, int64_t triangles) {
  state.counters["triangles"] = double(triangles);
  state.counters["Mtri/s"] =
      benchmark::Counter(double(triangles) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
}

// Extracts request r on the scene once per iteration; reports triangles/s, eps and the join.
void RunFrames(benchmark::State& state, const Scene& scene, const ExtractRequest& r) {
  int64_t triangles = 0;
  double join_ms = 0;
  for (auto _ : state) {
    auto res = Extract(*scene.hierarchy, scene.xf, r);
    triangles = res->stats.triangles;
    join_ms += res->stats.join_ms;
    benchmark::DoNotOptimize(res);
  }
  state.counters["eps"] = scene.request.eps;
  // The serial part: appending the subtrees' meshes in draw order.
  state.counters["join_ms"] = join_ms / double(state.iterations());
  Report(state, triangles);
}

// args: case, threads, sorted (1) or --order none (0)
void BM_Extract(benchmark::State& state) {
  const Scene& scene = GetScene(int(state.range(0)));
  ExtractRequest r = scene.request;
  r.threads = int(state.range(1));
  r.order = state.range(2) ? DrawOrder::kBackToFront : DrawOrder::kNone;
  RunFrames(state, scene, r);
}

// The same frames, 1 thread sorted, with the last three levels refined node by node instead of
// as blocks (ExtractRequest::blocks): what the blocks are worth. arg: case
void BM_ExtractNodeByNode(benchmark::State& state) {
  const Scene& scene = GetScene(int(state.range(0)));
  ExtractRequest r = scene.request;
  r.threads = 1;
  r.blocks = false;
  RunFrames(state, scene, r);
}

// The baseline Gerstner's method replaces: extract unsorted, then sort triangles by the
// distance of their centroids from the eye, farthest first.
void BM_ExtractThenSort(benchmark::State& state) {
  const Scene& scene = GetScene(int(state.range(0)));
  ExtractRequest r = scene.request;
  r.threads = int(state.range(1));
  r.order = DrawOrder::kNone;
  int64_t triangles = 0;
  for (auto _ : state) {
    auto res = Extract(*scene.hierarchy, scene.xf, r);
    OrderedMesh& m = res->mesh;
    const size_t t = m.triangle_count();
    std::vector<float> depth(t);
    const glm::vec3 eye(r.view.eye);
    for (size_t i = 0; i < t; ++i) {
      glm::vec3 c(0.0f);
      for (int j = 0; j < 3; ++j) {
        const float* p = &m.positions[3 * size_t(m.triangles[3 * i + j])];
        c += glm::vec3(p[0], p[1], p[2]);
      }
      const glm::vec3 d = c / 3.0f - eye;
      depth[i] = glm::dot(d, d);
    }
    std::vector<uint32_t> order(t);
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(),
              [&](uint32_t a, uint32_t b) { return depth[a] > depth[b]; });
    std::vector<uint32_t> tris(3 * t);
    std::vector<uint8_t> surface(t);
    for (size_t i = 0; i < t; ++i) {
      std::copy_n(&m.triangles[3 * size_t(order[i])], 3, &tris[3 * i]);
      surface[i] = m.surface[order[i]];
    }
    m.triangles.swap(tris);
    m.surface.swap(surface);
    triangles = int64_t(t);
    benchmark::DoNotOptimize(m);
  }
  Report(state, triangles);
}

// The budget search alone, as the first view of a (volume, isovalues, budget) pays it: the
// eps for the case's 1 M-triangle budget, found from scratch (no memo) by counting passes.
// args: case, threads
void BM_BudgetSearch(benchmark::State& state) {
  const Scene& scene = GetScene(int(state.range(0)));
  ExtractRequest r = scene.request;
  r.threads = int(state.range(1));
  r.budget = Cases()[size_t(state.range(0))].target_triangles;
  if (r.budget == 0) r.budget = 500000;  // cayley:257: half its eps 0 frame
  double eps = 0, passes = 0, triangles = 0;
  for (auto _ : state) {
    auto res = Extract(*scene.hierarchy, scene.xf, r);
    state.SetIterationTime(res->stats.budget_ms / 1e3);  // the search, not the extraction
    eps = res->stats.eps_used;
    passes = res->stats.budget_passes;
    triangles = double(res->stats.triangles);
  }
  state.counters["eps"] = eps;
  state.counters["passes"] = passes;
  state.counters["triangles"] = triangles;
}

// The frames of BM_Extract (1 thread, sorted) while also recording the cut for later views:
// what retaining costs the first view. arg: case
void BM_ExtractRetaining(benchmark::State& state) {
  const Scene& scene = GetScene(int(state.range(0)));
  ExtractRequest r = scene.request;
  r.threads = 1;
  int64_t triangles = 0;
  double megabytes = 0;
  RetainedCut cut;
  for (auto _ : state) {
    auto res = Extract(*scene.hierarchy, scene.xf, r, nullptr, &cut);
    triangles = res->stats.triangles;
    cut.KeepMesh(std::move(res->mesh));  // as isostreamd does once the frame is streamed
    benchmark::DoNotOptimize(res);
  }
  megabytes = double(cut.memory_bytes()) / (1 << 20);
  state.counters["cut_MiB"] = megabytes;
  Report(state, triangles);
}

// A view change served from the cut retained at the case's view: the eye circles the volume,
// 15 degrees per frame, and each frame is re-ordered (one thread) instead of extracted. arg:
// case
void BM_Reorder(benchmark::State& state) {
  const Scene& scene = GetScene(int(state.range(0)));
  ExtractRequest r = scene.request;
  RetainedCut cut;
  auto first = Extract(*scene.hierarchy, scene.xf, r, nullptr, &cut);
  if (!first.ok() || !cut.KeepMesh(std::move(first->mesh))) {
    state.SkipWithError("extraction failed");
    return;
  }
  int64_t triangles = 0, frame = 0;
  for (auto _ : state) {
    const double a = 0.2618 * double(frame++);
    View view = r.view;
    view.eye = {r.view.eye.x * std::cos(a) - r.view.eye.y * std::sin(a),
                r.view.eye.x * std::sin(a) + r.view.eye.y * std::cos(a), r.view.eye.z};
    auto res = Reorder(cut, view);
    triangles = res->stats.triangles;
    benchmark::DoNotOptimize(res);
  }
  Report(state, triangles);
}

void Args(benchmark::internal::Benchmark* b) {
  for (int c = 0; c < 4; ++c)
    for (int threads : {1, 2})
      for (int sorted : {1, 0}) b->Args({c, threads, sorted});
}
BENCHMARK(BM_Extract)->Apply(Args)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);
BENCHMARK(BM_ExtractNodeByNode)
    ->DenseRange(0, 3)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(1.0);
BENCHMARK(BM_BudgetSearch)
    ->ArgsProduct({{0, 1, 2, 3}, {1, 2}})
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->MinTime(1.0);
BENCHMARK(BM_ExtractThenSort)
    ->Args({0, 1})
    ->Args({2, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(1.0);

BENCHMARK(BM_ExtractRetaining)
    ->DenseRange(0, 3)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(1.0);
BENCHMARK(BM_Reorder)->DenseRange(0, 3)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);

}  // namespace
}  // namespace isostream

int main(int argc, char** argv) {
  isostream::KeepFreedMemoryForReuse();  // as isostreamd does: frames reuse freed memory
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
