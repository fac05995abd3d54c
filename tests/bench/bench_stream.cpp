// Streaming benchmark: frame codec sizes and speeds on a real ~1M-triangle view-ordered frame,
// and view change -> first chunk / complete frame at a client over loopback gRPC (an
// in-process isostreamd service on 127.0.0.1, the client library on the other end).
//
//   bench_stream [SPEC] [TRIANGLES] [VIEWS]      default: cayley:257 1000000 7
// VIEWS 0 prints the codec figures only.
#include <grpcpp/grpcpp.h>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "shared/malloc_tuning.h"
#include "client/net/session_client.h"
#include "server/extract/extractor.h"
#include "server/hierarchy/prepared_volume.h"
#include "server/service/catalogue.h"
#include "server/service/service.h"
#include "shared/frame_codec.h"
#include "shared/ply_io.h"

namespace {

using namespace isostream;
namespace pb = ::isostream::v1;
using Clock = std::chrono::steady_clock;

double Ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

// CPU time of this process (server and client threads), ms: steadier than wall time on a
// shared machine.
double CpuMs() {
  rusage u;
  getrusage(RUSAGE_SELF, &u);
  return 1e3 * (u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-3 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

const std::vector<float> kIso = {-0.5f, 0.0f, 0.5f};

glm::dvec3 Eye(int i) {
  const double a = 0.6 + 0.45 * i;
  return {3.5 * std::cos(a), 1.8 + 0.2 * (i % 3), 3.5 * std::sin(a)};
}

// Encodes `mesh` in 64k-triangle chunks with `encode` and decodes every chunk; returns bytes
// per triangle and encode/decode ms per million triangles.
struct CodecRun {
  double bytes_per_triangle = 0, encode_ms = 0, decode_ms = 0;
  bool ok = false;
};

template <typename EncodeFn>
CodecRun RunCodec(const OrderedMesh& mesh, EncodeFn encode, size_t chunk = 65536) {
  CodecRun run;
  size_t bytes = 0;
  std::string out;
  OrderedMesh decoded;
  for (size_t first = 0; first < mesh.triangle_count(); first += chunk) {
    const size_t n = std::min<size_t>(chunk, mesh.triangle_count() - first);
    const auto t0 = Clock::now();
    const absl::Status s = encode(first, n, &out);
    const auto t1 = Clock::now();
    if (!s.ok()) {
      std::printf("encode failed: %s\n", std::string(s.message()).c_str());
      return run;
    }
    if (!DecodeAnyChunk(out.data(), out.size(), &decoded).ok()) {
      std::printf("decode failed\n");
      return run;
    }
    run.encode_ms += Ms(t0, t1);
    run.decode_ms += Ms(t1, Clock::now());
    bytes += out.size();
  }
  const double per_m = 1e6 / double(mesh.triangle_count());
  run.bytes_per_triangle = double(bytes) / mesh.triangle_count();
  run.encode_ms *= per_m;
  run.decode_ms *= per_m;
  run.ok = true;
  return run;
}

// Where the bytes of the default codec go: header, Draco point cloud (positions, normals,
// surface index) and connectivity, per triangle. Normals and surface are measured by encoding
// without them (no normals; every triangle on surface 0).
void CodecBreakdown(const OrderedMesh& mesh, const CodecOptions& options) {
  double header = 0, points = 0, connectivity = 0, no_normals_points = 0, one_surface_points = 0;
  OrderedMesh bare = mesh;
  bare.normals.clear();
  OrderedMesh one_surface = mesh;
  std::fill(one_surface.surface.begin(), one_surface.surface.end(), 0);
  std::string out;
  for (size_t first = 0; first < mesh.triangle_count(); first += 65536) {
    const size_t n = std::min<size_t>(65536, mesh.triangle_count() - first);
    uint32_t points_size = 0;
    if (!EncodeChunk(mesh, first, n, options, &out).ok()) return;
    std::memcpy(&points_size, out.data() + kChunkHeaderSize, 4);
    header += kChunkHeaderSize + 4;
    points += points_size;
    connectivity += out.size() - kChunkHeaderSize - 4 - points_size;
    if (!EncodeChunk(bare, first, n, options, &out).ok()) return;
    std::memcpy(&points_size, out.data() + kChunkHeaderSize, 4);
    no_normals_points += points_size;
    if (!EncodeChunk(one_surface, first, n, options, &out).ok()) return;
    std::memcpy(&points_size, out.data() + kChunkHeaderSize, 4);
    one_surface_points += points_size;
  }
  const double t = double(mesh.triangle_count());
  std::printf(
      "  default codec by part (B/tri): connectivity %.3f, vertex attributes %.3f (normals "
      "%.3f, surface index %.3f, positions and framing %.3f), chunk headers %.4f\n",
      connectivity / t, points / t, (points - no_normals_points) / t,
      (points - one_surface_points) / t, (no_normals_points - (points - one_surface_points)) / t,
      header / t);
}

void CodecFigures(const OrderedMesh& mesh, const Volume& volume) {
  QuantizationBox box;
  int bits;
  QuantizationFor(volume, &box, &bits);
  const double voxel = std::min({volume.spacing[0], volume.spacing[1], volume.spacing[2]});
  std::printf(
      "\ncodec on the frame: %zu triangles, %zu vertices, normals and surface index, "
      "64k-triangle chunks, positions %d bits on the volume box (max error %.2g = %.4f voxel), "
      "normals 10 bits (max error %.2g rad)\n",
      mesh.triangle_count(), mesh.vertex_count(), bits, PositionErrorBound(box, bits),
      PositionErrorBound(box, bits) / voxel, NormalErrorBound(10));
  std::printf("  %-40s %10s %12s %12s\n", "codec", "bytes/tri", "encode ms/1M", "decode ms/1M");
  using Connectivity = CodecOptions::Connectivity;
  struct Variant {
    const char* name;
    bool raw;
    Connectivity connectivity;
    bool compress;
    int position_bits_less;  // below the daemon's choice
    int normal_bits;
  };
  for (const Variant& v : {
           Variant{"edge cache (default)", false, Connectivity::kEdgeCache, true, 0, 10},
           Variant{"draco sequential + connectivity", false, Connectivity::kDracoSequential, true,
                   0, 10},
           Variant{"draco sequential", false, Connectivity::kDracoSequential, false, 0, 10},
           Variant{"raw", true, Connectivity::kEdgeCache, false, 0, 0},
           Variant{"edge cache, positions 1/32 voxel", false, Connectivity::kEdgeCache, true, 1,
                   10},
           Variant{"edge cache, normals 8 bits", false, Connectivity::kEdgeCache, true, 0, 8},
           Variant{"edge cache, 1/32 voxel, normals 8", false, Connectivity::kEdgeCache, true, 1,
                   8},
           Variant{"draco seq + conn, 1/32 voxel, normals 8", false, Connectivity::kDracoSequential,
                   true, 1, 8},
       }) {
    CodecOptions o;
    o.connectivity = v.connectivity;
    o.position_bits = bits - v.position_bits_less;
    o.normal_bits = v.normal_bits;
    o.compress_connectivity = v.compress;
    o.position_box = box;
    const CodecRun run = RunCodec(mesh, [&](size_t first, size_t n, std::string* out) {
      return v.raw ? EncodeChunkRaw(mesh, first, n, out) : EncodeChunk(mesh, first, n, o, out);
    });
    if (!run.ok) return;
    std::printf("  %-40s %10.2f %12.1f %12.1f\n", v.name, run.bytes_per_triangle, run.encode_ms,
                run.decode_ms);
  }
  CodecOptions o;
  o.position_bits = bits;
  o.position_box = box;
  CodecBreakdown(mesh, o);
  std::printf("  default codec by chunk size (B/tri):");
  for (size_t chunk : {4096, 8192, 16384, 32768, 65536}) {
    const CodecRun run = RunCodec(
        mesh,
        [&](size_t first, size_t n, std::string* out) {
          return EncodeChunk(mesh, first, n, o, out);
        },
        chunk);
    std::printf(" %zuk %.2f", chunk / 1024, run.bytes_per_triangle);
  }
  std::printf("\n");
}

// What `extract -o` and `fetch -o` pay to write the frame as binary PLY, and to read it back.
void PlyFigures(const OrderedMesh& mesh) {
  double write_ms = 1e300, read_ms = 1e300;
  std::string bytes;
  for (int run = 0; run < 3; ++run) {  // best of 3: the machine is shared
    const Clock::time_point t0 = Clock::now();
    if (!SerializePly(mesh, true, &bytes).ok()) return;
    const Clock::time_point t1 = Clock::now();
    if (!ParsePly(bytes).ok()) return;
    const Clock::time_point t2 = Clock::now();
    write_ms = std::min(write_ms, Ms(t0, t1));
    read_ms = std::min(read_ms, Ms(t1, t2));
  }
  const double per_million = 1e6 / double(std::max<size_t>(mesh.triangle_count(), 1));
  std::printf("  binary PLY: %.2f bytes/tri, write %.1f ms/1M, read %.1f ms/1M\n",
              double(bytes.size()) / double(std::max<size_t>(mesh.triangle_count(), 1)),
              write_ms * per_million, read_ms * per_million);
}

struct ViewTiming {
  double first_chunk_ms, complete_ms, server_extract_ms;
  int64_t triangles, bytes;
  bool reordered;
};

// Sends `view` on the session and reads its frame; decodes when `decode`.
bool RunView(net::Session* s, const pb::ViewRequest& view, bool decode, ViewTiming* t) {
  const auto t0 = Clock::now();
  if (!s->Send(view).ok()) return false;
  net::FrameAssembler assembler;
  pb::FrameChunk chunk;
  bool first = true;
  t->bytes = 0;
  while (s->Read(&chunk)) {
    if (chunk.frame_id() != view.request_id()) continue;
    if (first) {
      t->first_chunk_ms = Ms(t0, Clock::now());
      first = false;
    }
    t->bytes += int64_t(chunk.data().size());
    if (decode && !assembler.Add(chunk).ok()) return false;
    if (chunk.last()) {
      t->complete_ms = Ms(t0, Clock::now());
      t->triangles = chunk.stats().triangles();
      t->server_extract_ms = chunk.stats().extract_ms();
      t->reordered = chunk.stats().reordered();
      return true;
    }
  }
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  KeepFreedMemoryForReuse();  // as isostreamd does
  const std::string spec = argc > 1 ? argv[1] : "cayley:257";
  const int64_t target = argc > 2 ? std::atoll(argv[2]) : 1'000'000;
  const int views = argc > 3 ? std::atoi(argv[3]) : 7;

  HierarchyCacheOptions cache;
  cache.dir = DefaultCacheDir();
  auto prepared = PrepareVolume(spec, VolumeLimits{}, cache, HierarchyBuildOptions{});
  if (!prepared.ok()) {
    std::fprintf(stderr, "bench_stream: %s\n", std::string(prepared.status().message()).c_str());
    return 1;
  }
  ExtractRequest r;
  r.isovalues = kIso;
  r.budget = target;
  r.view.eye = Eye(0);
  auto frame = Extract(*prepared->hierarchy, prepared->grid_to_world, r);
  if (!frame.ok()) return 1;
  const double eps = frame->stats.eps_used;
  std::printf(
      "volume %s, isovalues -0.5 0 0.5, budget %lld -> eps %.4g, %lld triangles "
      "(direct extraction %.0f ms)\n",
      spec.c_str(), (long long)target, eps, (long long)frame->stats.triangles,
      frame->stats.total_ms);
  CodecFigures(frame->mesh, *prepared->volume);
  PlyFigures(frame->mesh);
  if (views < 1) return 0;

  // The daemon's service in this process, on a free loopback port: once retaining nothing
  // (every view is extracted), once as the daemon runs by default (a session's new view of
  // the same mesh is re-ordered from its last frame).
  for (const int64_t retain_mb : {int64_t{0}, service::DaemonConfig().retain_mb}) {
    service::DaemonConfig config;
    config.listen = "127.0.0.1:0";
    config.retain_mb = retain_mb;
    config.cache_dir = cache.dir;
    config.limits.max_dim = 1025;
    config.limits.max_triangles = 8'000'000;
    service::IsostreamService svc(config);
    grpc::ServerBuilder builder;
    int port = 0;
    builder.AddListeningPort(config.listen, grpc::InsecureServerCredentials(), &port);
    builder.RegisterService(&svc);
    auto server = builder.BuildAndStart();
    if (!server || port == 0) return 1;
    net::ClientOptions options;
    options.address = "127.0.0.1:" + std::to_string(port);
    auto client = net::Client::Connect(options);
    if (!client.ok()) return 1;

    std::printf(
        "\nview change -> frame at the client over loopback gRPC (eps %.4g, %d views, "
        "median [min]; extract ms: the server's extraction alone), %s\n",
        eps, views,
        retain_mb > 0 ? "frames retained: the same mesh re-ordered for each new view"
                      : "nothing retained: every view extracted");
    std::printf("  %-7s %-8s %10s %16s %16s %12s %10s %8s %10s\n", "codec", "decoded",
                "triangles", "first chunk ms", "complete ms", "extract ms", "bytes/tri", "cpu ms",
                "re-ordered");
    for (pb::Codec codec : {pb::DRACO, pb::RAW}) {
      for (bool decode : {false, true}) {
        auto session = (*client)->OpenSession();
        if (!session.ok()) return 1;
        std::vector<double> first, complete, extract;
        int reordered = 0;
        ViewTiming t{};
        double cpu_start = 0;
        for (int i = -1; i < views; ++i) {  // view -1 warms the volume and the connection
          pb::ViewRequest v;
          v.set_volume(spec);
          v.set_request_id(uint64_t(i + 2));
          for (float iso : kIso) v.add_surfaces()->set_isovalue(iso);
          v.set_eps(eps);
          const glm::dvec3 e = Eye(i + 1);
          v.mutable_camera()->mutable_eye()->set_x(e.x);
          v.mutable_camera()->mutable_eye()->set_y(e.y);
          v.mutable_camera()->mutable_eye()->set_z(e.z);
          v.set_codec(codec);
          if (!RunView(session->get(), v, decode, &t)) {
            std::fprintf(stderr, "bench_stream: view failed\n");
            return 1;
          }
          if (i < 0) {
            cpu_start = CpuMs();
            continue;
          }
          reordered += t.reordered;
          first.push_back(t.first_chunk_ms);
          complete.push_back(t.complete_ms);
          extract.push_back(t.server_extract_ms);
        }
        const double cpu_per_view = (CpuMs() - cpu_start) / views;
        std::printf("  %-7s %-8s %10lld %8.1f [%5.1f] %8.1f [%5.1f] %12.1f %10.2f %8.0f %7d/%d\n",
                    codec == pb::RAW ? "raw" : "draco", decode ? "yes" : "no", (long long)t.triangles,
                    Median(first), *std::min_element(first.begin(), first.end()), Median(complete),
                    *std::min_element(complete.begin(), complete.end()), Median(extract),
                    double(t.bytes) / double(std::max<int64_t>(1, t.triangles)), cpu_per_view,
                    reordered, views);
        (*session)->CloseSend().IgnoreError();
        (*session)->Finish().IgnoreError();
      }
    }
    // Progressive: the coarse frame (20k-triangle budget) first, then the refined one.
    {
      auto session = (*client)->OpenSession();
      if (!session.ok()) return 1;
      std::vector<double> first, coarse, refined;
      for (int i = -1; i < views; ++i) {
        pb::ViewRequest v;
        v.set_volume(spec);
        v.set_request_id(uint64_t(100 + i));
        for (float iso : kIso) v.add_surfaces()->set_isovalue(iso);
        v.set_eps(eps);
        v.set_progressive(true);
        const glm::dvec3 e = Eye(i + 1);
        v.mutable_camera()->mutable_eye()->set_x(e.x);
        v.mutable_camera()->mutable_eye()->set_y(e.y);
        v.mutable_camera()->mutable_eye()->set_z(e.z);
        const auto t0 = Clock::now();
        if (!(*session)->Send(v).ok()) return 1;
        pb::FrameChunk chunk;
        double t_first = -1, t_coarse = -1;
        while ((*session)->Read(&chunk)) {
          if (chunk.frame_id() != v.request_id()) continue;
          if (t_first < 0) t_first = Ms(t0, Clock::now());
          if (chunk.last() && chunk.coarse()) t_coarse = Ms(t0, Clock::now());
          if (chunk.last() && !chunk.coarse()) break;
        }
        if (i < 0) continue;
        first.push_back(t_first);
        coarse.push_back(t_coarse);
        refined.push_back(Ms(t0, Clock::now()));
      }
      std::printf(
          "\nprogressive (draco, not decoded): first chunk %.1f ms, coarse frame complete "
          "%.1f ms (-1: none sent), refined frame complete %.1f ms (medians)\n",
          Median(first), Median(coarse), Median(refined));
      (*session)->CloseSend().IgnoreError();
      (*session)->Finish().IgnoreError();
    }
  server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(1));
  }
  return 0;
}
