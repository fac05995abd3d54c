// Client draw cost on llvmpipe: upload a ~1 M-triangle frame (three nested icospheres in
// painter's order) and draw it blended at 1024x768, as chunks the way frames arrive, and draw
// an already uploaded frame. Figure: ms_per_Mtri, wall time per iteration per 10^6 triangles.
//   cmake --build build --target bench_render && build/client/bench_render
// Measured (Debian 12, Mesa 22.3.6 llvmpipe, 2 cores, median of 5): upload + draw 117-123 ms per
// 10^6 triangles (upload alone ~5), redraw 115, redraw covering ~1% of the pixels 73: the
// per-triangle vertex stage, not blending, is most of the cost.
#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <vector>

#include "client/render/headless_context.h"
#include "client/render/mesh_renderer.h"
#include "tests/render/test_spheres.h"

namespace isostream::render {
namespace {

struct Fixture {
  std::unique_ptr<HeadlessContext> context;
  std::unique_ptr<MeshRenderer> renderer;
  Camera camera;
  OrderedMesh mesh;

  static Fixture& Get() {
    static Fixture* fixture = [] {
      auto* f = new Fixture;
      HeadlessContextOptions options;
      options.width = 1024;
      options.height = 768;
      auto context = HeadlessContext::Create(options);
      if (!context.ok()) {
        std::fprintf(stderr, "%s\n", std::string(context.status().message()).c_str());
        std::exit(1);
      }
      f->context = std::move(*context);
      auto renderer = MeshRenderer::Create();
      if (!renderer.ok()) std::exit(1);
      f->renderer = std::move(*renderer);
      Camera base;
      base.aspect = 1024.0f / 768.0f;
      f->camera = FrameBox(glm::vec3(-0.75f), glm::vec3(0.75f), glm::vec3(0.5f, 0.4f, 1.0f), base);
      // 3 x 20 x 4^7 = 983,040 triangles.
      f->mesh = testing::MakeSpheres(testing::ThreeNestedSpheres(), 7);
      testing::SortShellsBackToFront(f->camera, {}, &f->mesh);
      std::fprintf(stderr, "renderer: %s, %zu triangles, %zu vertices\n",
                   f->context->renderer_name().c_str(), f->mesh.triangle_count(),
                   f->mesh.vertex_count());
      return f;
    }();
    return *fixture;
  }
};

// Splits the frame into `count` self-contained chunk meshes, as a decoder would hand them over.
std::vector<OrderedMesh> SplitIntoChunks(const OrderedMesh& mesh, size_t count) {
  std::vector<OrderedMesh> chunks(count);
  const size_t n = mesh.triangle_count();
  for (size_t c = 0; c < count; ++c) {
    const size_t first = n * c / count, last = n * (c + 1) / count;
    OrderedMesh& out = chunks[c];
    std::vector<uint32_t> remap(mesh.vertex_count(), UINT32_MAX);
    for (size_t i = 3 * first; i < 3 * last; ++i) {
      uint32_t& slot = remap[mesh.triangles[i]];
      if (slot == UINT32_MAX) {
        slot = uint32_t(out.vertex_count());
        const size_t v = mesh.triangles[i];
        out.positions.insert(out.positions.end(), &mesh.positions[3 * v],
                             &mesh.positions[3 * v + 3]);
        out.normals.insert(out.normals.end(), &mesh.normals[3 * v], &mesh.normals[3 * v + 3]);
      }
      out.triangles.push_back(slot);
    }
    out.surface.assign(mesh.surface.begin() + first, mesh.surface.begin() + last);
  }
  return chunks;
}

// Wall time per iteration per 10^6 triangles, in ms, as a plain number in the output.
class MsPerMillionTriangles {
 public:
  void Start() { start_ = std::chrono::steady_clock::now(); }
  void Stop() {
    total_ms_ +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_)
            .count();
  }
  void Report(benchmark::State& state, size_t triangles) const {
    if (state.iterations() == 0) return;
    state.counters["ms_per_Mtri"] = total_ms_ / double(state.iterations()) / (triangles / 1e6);
    state.counters["triangles"] = double(triangles);
  }

 private:
  std::chrono::steady_clock::time_point start_;
  double total_ms_ = 0.0;
};

// Upload (BeginFrame, AddChunk per chunk, EndFrame) plus one blended draw, finished.
void BM_UploadAndDraw(benchmark::State& state) {
  Fixture& f = Fixture::Get();
  const std::vector<OrderedMesh> chunks = SplitIntoChunks(f.mesh, size_t(state.range(0)));
  MsPerMillionTriangles timer;
  for (auto _ : state) {
    timer.Start();
    f.renderer->BeginFrame();
    for (const OrderedMesh& c : chunks) {
      if (!f.renderer->AddChunk(c).ok()) state.SkipWithError("AddChunk failed");
    }
    if (!f.renderer->EndFrame().ok() || !f.renderer->Render(f.camera).ok() ||
        !f.context->Finish().ok()) {
      state.SkipWithError("draw failed");
    }
    timer.Stop();
  }
  timer.Report(state, f.mesh.triangle_count());
}
BENCHMARK(BM_UploadAndDraw)->Arg(1)->Arg(16)->Arg(64)->Unit(benchmark::kMillisecond)->UseRealTime();

// Drawing a frame already on the GPU: what a viewer pays per redraw (e.g. while orbiting).
// Arg 1 = 1: the spheres seen from 12x as far, covering ~1% of the pixels instead of ~40%, to
// separate the per-triangle cost from the per-pixel (blending, shading, ~6 layers) cost.
void BM_DrawOnly(benchmark::State& state) {
  Fixture& f = Fixture::Get();
  f.renderer->BeginFrame();
  for (const OrderedMesh& c : SplitIntoChunks(f.mesh, size_t(state.range(0)))) {
    if (!f.renderer->AddChunk(c).ok()) state.SkipWithError("AddChunk failed");
  }
  if (!f.renderer->EndFrame().ok()) state.SkipWithError("EndFrame failed");
  Camera camera = f.camera;
  if (state.range(1) == 1) {
    camera.eye = camera.target + 12.0f * (camera.eye - camera.target);
    camera.far_plane *= 12.0f;
  }
  MsPerMillionTriangles timer;
  for (auto _ : state) {
    timer.Start();
    if (!f.renderer->Render(camera).ok() || !f.context->Finish().ok())
      state.SkipWithError("draw failed");
    timer.Stop();
  }
  timer.Report(state, f.mesh.triangle_count());
}
BENCHMARK(BM_DrawOnly)
    ->Args({1, 0})
    ->Args({16, 0})
    ->Args({16, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// Upload alone, finished: the part a chunk stream adds on top of drawing.
void BM_UploadOnly(benchmark::State& state) {
  Fixture& f = Fixture::Get();
  const std::vector<OrderedMesh> chunks = SplitIntoChunks(f.mesh, size_t(state.range(0)));
  MsPerMillionTriangles timer;
  for (auto _ : state) {
    timer.Start();
    f.renderer->BeginFrame();
    for (const OrderedMesh& c : chunks) {
      if (!f.renderer->AddChunk(c).ok()) state.SkipWithError("AddChunk failed");
    }
    if (!f.renderer->EndFrame().ok() || !f.context->Finish().ok())
      state.SkipWithError("upload failed");
    timer.Stop();
  }
  timer.Report(state, f.mesh.triangle_count());
}
BENCHMARK(BM_UploadOnly)->Arg(16)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace isostream::render

BENCHMARK_MAIN();
