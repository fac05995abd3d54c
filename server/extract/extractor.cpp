// Drives the traversal (traversal.h): validation, the split into subtrees, parallel
// extraction, the ordered join, and the eps search for a triangle budget.
//
// Parallel output: subtrees are cut from the top of the tree in draw order, extracted
// independently, and appended in that order as soon as each prefix is complete, so the result
// is the single-thread result whatever the thread count, and an observer sees the farthest
// triangles first. Vertices on a subtree's boundary faces are merged by edge key on append.
#include "server/extract/extractor.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>
#include <limits>
#include <mutex>
#include <numeric>
#include <optional>

#include "server/extract/budget_search.h"
#include "server/extract/retained_cut.h"
#include "server/extract/traversal.h"
#include "server/extract/view_context.h"
#include "shared/arena_size.h"

namespace isostream {

using extract_internal::ClipVertexIds;
using extract_internal::Context;
using extract_internal::CountCurve;
using extract_internal::Decide;
using extract_internal::Decision;
using extract_internal::Node;
using extract_internal::SubtreeMesh;
using extract_internal::SubtreeMeshPool;
using extract_internal::Traverser;

absl::Status ValidateRequest(const ExtractRequest& r) {
  if (r.isovalues.empty()) return absl::InvalidArgumentError("no isovalue given");
  if (r.isovalues.size() > size_t(kMaxSurfaces))
    return absl::InvalidArgumentError("at most " + std::to_string(kMaxSurfaces) +
                                      " isovalues per request, got " +
                                      std::to_string(r.isovalues.size()));
  for (float v : r.isovalues)
    if (!std::isfinite(v)) return absl::InvalidArgumentError("isovalue is not a finite number");
  // One surface drawn twice would blend over itself; a repeated value is a caller's mistake.
  std::vector<float> sorted = r.isovalues;
  std::sort(sorted.begin(), sorted.end());
  for (size_t i = 1; i < sorted.size(); ++i)
    if (sorted[i] == sorted[i - 1]) {
      char shown[32];
      std::snprintf(shown, sizeof(shown), "%g", double(sorted[i]));
      return absl::InvalidArgumentError(std::string("isovalue ") + shown +
                                        " is given twice (isovalues are compared in single "
                                        "precision, as the samples are)");
    }
  if (r.budget < 0) return absl::InvalidArgumentError("triangle budget must be positive");
  if (r.budget == 0 && !(r.eps >= 0 && std::isfinite(r.eps)))
    return absl::InvalidArgumentError("eps must be a finite number >= 0");
  if (r.threads < 0) return absl::InvalidArgumentError("threads must be >= 0");
  const glm::dvec3& d = r.view.orthographic ? r.view.direction : r.view.eye;
  if (!std::isfinite(d.x) || !std::isfinite(d.y) || !std::isfinite(d.z))
    return absl::InvalidArgumentError("view is not finite");
  if (r.view.orthographic && d.x == 0 && d.y == 0 && d.z == 0)  // (a subnormal one is a sense)
    return absl::InvalidArgumentError("view direction is zero");
  return absl::OkStatus();
}

namespace {

double Ms(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - since)
      .count();
}

Context MakeContext(const Hierarchy& h, const GridToWorld& xf, const ExtractRequest& r,
                    double eps) {
  Context c;
  c.store = reinterpret_cast<const char*>(h.bricks());
  for (int a = 0; a < 3; ++a) {
    c.value_bytes[a] = h.value_byte_offsets()[a].data();
    c.eta_bytes[a] = h.eta_byte_offsets()[a].data();
  }
  c.k = h.k();
  c.n = h.n();
  for (int a = 0; a < 3; ++a) c.data_max[a] = h.data_dims()[a] - 1;
  c.clip = c.data_max.x < c.n - 1 || c.data_max.y < c.n - 1 || c.data_max.z < c.n - 1;
  std::vector<std::pair<float, int>> sorted;
  for (size_t i = 0; i < r.isovalues.size(); ++i) sorted.push_back({r.isovalues[i], int(i)});
  std::sort(sorted.begin(), sorted.end());
  c.iso_count = 0;
  for (size_t i = 0; i < sorted.size(); ++i) {  // distinct: ValidateRequest refuses repeats
    c.iso[c.iso_count] = sorted[i].first;
    c.iso_surface[c.iso_count++] = uint8_t(sorted[i].second);
  }
  // An eps past the float range (the budget search's cap for etas of +inf) stops nowhere
  // finite etas do not: +inf, written out (the conversion itself would be undefined).
  c.eps = eps > double(std::numeric_limits<float>::max()) ? std::numeric_limits<float>::infinity()
                                                          : static_cast<float>(eps);
  if (double(c.eps) < eps) c.eps = std::nextafter(c.eps, INFINITY);  // stop only if eta < eps
  extract_internal::SetView(&c, xf, r.view, r.order);
  c.normals = r.normals;
  c.xf = xf;
  c.world_origin = glm::vec3(xf.origin);
  c.world_spacing = glm::vec3(xf.spacing);
  c.inv_spacing = glm::vec3(1.0 / xf.spacing);
  c.snap_tau = extract_internal::SnapTau(c.world_origin, c.world_spacing, c.n - 1);
  c.tables = &ReferenceTets::Get();
  c.blocks = &BlockTables::Get();
  c.block_level = r.blocks ? 3 * c.k - kBlockDepth : -1;
  c.cases = &MarchingTets::Get();
  for (int i = 0; i < kNumTetClasses; ++i)
    c.negative[i] = (*c.tables)[TetClass{uint8_t(i)}].left_handed;
  for (int level = 0; level <= 3 * c.k; ++level)
    c.inv_unit[level] = 2.0 / double((1 << c.k) >> (level / 3));
  return c;
}

// A count pass's context: a count does not depend on the draw order, so the pass neither
// decides which child comes first (a plane side per node) nor orders a leaf's components (a
// gradient); Traverser<false> leaves the §5 gradients out too.
Context MakeCountContext(const Hierarchy& h, const GridToWorld& xf, const ExtractRequest& r,
                         double eps) {
  Context c = MakeContext(h, xf, r, eps);
  c.ordered = false;
  return c;
}

// Cuts the top of the tree into subtrees in draw order. Deterministic (independent of the
// thread count) so the output is too. With a curve (a count pass that gathers one), the nodes
// refined here add their share to it as the traversal's do, and pass their eta caps down.
// With `top`, the refinements are recorded there too.
std::vector<Node> SplitIntoSubtrees(const Context& c, extract_internal::CountCurve* curve = nullptr,
                                    extract_internal::SplitTree* top = nullptr) {
  const ReferenceTets& tables = *c.tables;
  const int size = 1 << c.k;
  int order[kNumInitialTets];
  if (c.ordered) {
    tables.InitialOrder(c.orthographic ? c.dir : c.eye / double(size), c.orthographic, order);
  } else {
    std::iota(order, order + kNumInitialTets, 0);
  }
  std::vector<Node> items;
  std::vector<int> ids;  // items' entries in *top
  for (int i : order) {
    Node t;
    const TetVertices v = InitialVertices(tables, i, size);
    for (int j = 0; j < 4; ++j) {
      t.v[j] = extract_internal::Pack(v[j]);
      t.f[j] = c.F(v[j]);
    }
    const glm::dmat3 e(glm::dvec3(v[1] - v[0]), glm::dvec3(v[2] - v[0]), glm::dvec3(v[3] - v[0]));
    // Float differences as always; in double where they overflow (samples near FLT_MAX).
    auto diff = [](float a, float b) {
      const float d = a - b;
      return std::isfinite(d) ? double(d) : double(a) - double(b);
    };
    const glm::dvec3 df(diff(t.f[1], t.f[0]), diff(t.f[2], t.f[0]), diff(t.f[3], t.f[0]));
    t.g = glm::inverse(glm::transpose(e)) * df;  // the only direct solve: the six roots
    t.cls = tables.initial_class(i);
    t.level = 0;
    const extract_internal::PackedPoint x = extract_internal::Pack(RefinementPoint(v));
    t.xref_value = c.ValueOffset(x);
    t.xref_eta = c.EtaOffset(x);
    t.child0_first = extract_internal::ChildZeroFirst(c, t.cls, x);
    t.eta_cap = kInfiniteEtaCode;
    items.push_back(t);
    if (top) {
      ids.push_back(int(top->entries.size()));
      top->roots.push_back({i, ids.back()});
      top->entries.emplace_back();
    }
  }
  constexpr size_t kTargetSubtrees = 256;
  constexpr int kMaxSplitLevel = 15;
  for (int level = 0; level < kMaxSplitLevel && items.size() < kTargetSubtrees; ++level) {
    std::vector<Node> next;
    std::vector<int> next_ids;
    bool refined = false;
    for (size_t j = 0; j < items.size(); ++j) {
      const Node& t = items[j];
      const Decision d = Decide(c, t);
      if (d == Decision::kCull) {
        if (curve && t.level < 3 * c.k)  // as the traversal does
          curve->NoteStop(extract_internal::EtaCode(c, t));
        continue;
      }
      if (d == Decision::kLeaf) {
        next.push_back(t);
        if (top) next_ids.push_back(ids[j]);
        continue;
      }
      Node kids[2];
      extract_internal::Bisect(c, t, &kids[0], &kids[1]);
      if (top) {
        const int e = ids[j], kid = int(top->entries.size());
        top->entries.resize(kid + 2);
        extract_internal::SplitTree::Entry& n = top->entries[e];
        n.plane_side = extract_internal::PlaneSide(c, t.cls, (t.v[0] + t.v[3]) >> 1);
        n.cls = t.cls;
        n.child0_first = t.child0_first;
        n.kids[0] = kid, n.kids[1] = kid + 1;
        next_ids.push_back(kid);
        next_ids.push_back(kid + 1);
      }
      if (curve) {
        const uint32_t code = extract_internal::EtaCode(c, t);
        curve->Add(code + 1, t.eta_cap, extract_internal::LeafTriangles(c, t));
        kids[0].eta_cap = kids[1].eta_cap = std::min(t.eta_cap, code);
      }
      next.push_back(kids[0]);
      next.push_back(kids[1]);
      refined = true;
    }
    items.swap(next);
    ids.swap(next_ids);
    if (!refined) break;
  }
  if (top)
    for (size_t i = 0; i < items.size(); ++i) top->entries[ids[i]].item = int(i);
  return items;
}

// Why an observed extraction must stop now (cancelled, or past its deadline), or OK.
absl::Status StopReason(const ExtractObserver* observer) {
  if (observer == nullptr) return absl::OkStatus();
  if (observer->cancel && observer->cancel->load(std::memory_order_relaxed))
    return absl::CancelledError("extraction cancelled");
  if (observer->deadline != std::chrono::steady_clock::time_point::max() &&
      std::chrono::steady_clock::now() > observer->deadline)
    return absl::DeadlineExceededError("extraction passed its deadline");
  return absl::OkStatus();
}

// A count pass stopped by its observer sets *stopped (its count is then meaningless). With a
// curve, `c` must have blocks off, and the curve is complete only if the count is <= limit.
int64_t CountAt(const Context& c, int64_t limit, const ExtractObserver* observer = nullptr,
                absl::Status* stopped = nullptr, CountCurve* curve = nullptr) {
  const std::vector<Node> items = SplitIntoSubtrees(c, curve);
  std::atomic<int64_t> total{0};
  std::atomic<bool> halted{false};
  // One curve per worker thread, summed at the end (a few to a few hundred KB each).
  std::optional<tbb::enumerable_thread_specific<CountCurve>> curves;
  if (curve) curves.emplace(curve->first(), curve->last());
  tbb::parallel_for(size_t(0), items.size(), [&](size_t i) {
    if (total.load(std::memory_order_relaxed) > limit || halted.load()) return;
    if (observer && !StopReason(observer).ok()) {
      halted = true;
      return;
    }
    Traverser<false> t(c, nullptr, nullptr, curve ? &curves->local() : nullptr);
    total += t.Run(items[i], limit);
  });
  if (curve)
    for (const CountCurve& part : *curves) curve->Merge(part);
  if (halted && stopped) *stopped = StopReason(observer);
  // Past the limit the sum depends on which subtrees ran before the others stopped (thread
  // timing): report limit + 1, so the budget search is deterministic and view-independent.
  const int64_t n = total.load();
  return n > limit ? limit + 1 : n;
}

}  // namespace

absl::StatusOr<int64_t> CountTriangles(const Hierarchy& h, const GridToWorld& xf,
                                       const ExtractRequest& r, double eps, int64_t limit) {
  ISOSTREAM_RETURN_IF_ERROR(ValidateRequest(r));
  const Context c = MakeCountContext(h, xf, r, eps);
  tbb::task_arena arena(ArenaSize(r.threads));
  return arena.execute([&] { return CountAt(c, limit); });
}

double EtaCodeEps(uint32_t code) {
  if (code >= kInfiniteEtaCode) return double(std::numeric_limits<float>::max());
  return DecodeEta(uint16_t(code));
}

uint32_t EtaCodeAtLeast(double eps) {
  if (!(eps > 0)) return 0;
  if (eps > double(std::numeric_limits<float>::max())) return kInfiniteEtaCode;
  float f = float(eps);
  if (double(f) < eps) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return std::min<uint32_t>(EncodeEtaRoundingUp(f), kInfiniteEtaCode);
}

uint32_t CoarsestEtaCode(const Hierarchy& h) {
  const int half = (h.n() - 1) / 2;
  return std::min(EtaCodeAtLeast(h.eta(half, half, half)) + 1, kInfiniteEtaCode);
}

absl::StatusOr<std::vector<int64_t>> CountTrianglesPerEtaCode(const Hierarchy& h,
                                                              const GridToWorld& xf,
                                                              const ExtractRequest& r,
                                                              uint32_t first_code,
                                                              uint32_t last_code) {
  ISOSTREAM_RETURN_IF_ERROR(ValidateRequest(r));
  if (first_code > last_code || last_code > kInfiniteEtaCode)
    return absl::InvalidArgumentError("eta codes must satisfy first <= last <= 0x7f80");
  Context c = MakeCountContext(h, xf, r, EtaCodeEps(first_code));
  c.block_level = -1;
  CountCurve curve(first_code, last_code);
  tbb::task_arena arena(ArenaSize(r.threads));
  arena.execute([&] { CountAt(c, INT64_MAX, nullptr, nullptr, &curve); });
  return curve.Counts();
}

absl::StatusOr<ExtractResult> Extract(const Hierarchy& h, const GridToWorld& xf,
                                      const ExtractRequest& r, const ExtractObserver* observer,
                                      RetainedCut* retain) {
  if (retain) retain->Clear();
  ISOSTREAM_RETURN_IF_ERROR(ValidateRequest(r));
  const auto t_start = std::chrono::steady_clock::now();
  ExtractResult result;
  ExtractStats& st = result.stats;
  tbb::task_arena arena(ArenaSize(r.threads));

  double eps = r.eps;
  std::optional<double> remembered;
  std::optional<int64_t> counted;  // triangles at eps, when the budget search measured them
  if (r.budget > 0 && r.budget_memo) remembered = r.budget_memo->Find(r.isovalues, r.budget);
  if (remembered) {
    eps = *remembered;
  } else if (r.budget > 0) {
    // Triangle count never grows with eps (saturated eta nests the meshes; clipping at the
    // data box can break this at a few codes: ARCHITECTURE.md, "Budget") and changes only
    // at eta codes: the answer is the smallest code whose count fits (budget_search.h), found
    // by passes that count only, stop at 4x the budget and gather the count at every coarser
    // code on the way (count_curve.h; node by node, as blocks skip the etas it needs).
    auto t0 = std::chrono::steady_clock::now();
    // Saturated: a budget past any frame ("everything") must not overflow the limit.
    constexpr int64_t kMaxLimit = std::numeric_limits<int64_t>::max() / 2;
    const int64_t limit = r.budget > kMaxLimit / 4 ? kMaxLimit : 4 * r.budget;
    // A stopped pass ends the search: the request is answered with why, and nothing is
    // remembered.
    absl::Status stopped;
    auto count_at = [&](uint32_t code, CountCurve* curve) -> std::optional<int64_t> {
      if (stopped.ok()) stopped = StopReason(observer);
      if (!stopped.ok()) return std::nullopt;
      Context c = MakeCountContext(h, xf, r, EtaCodeEps(code));
      if (curve) c.block_level = -1;
      const int64_t n = CountAt(c, limit, observer, &stopped, curve);
      if (!stopped.ok()) return std::nullopt;
      return n;
    };
    const extract_internal::BudgetSearchResult found = arena.execute([&] {
      return extract_internal::FindBudgetCode(r.budget, limit, CoarsestEtaCode(h), count_at);
    });
    st.budget_passes = found.passes;
    eps = EtaCodeEps(found.code);
    counted = found.count;
    if (!stopped.ok()) return stopped;
    st.budget_ms = Ms(t0);
    if (r.budget_memo) r.budget_memo->Store(r.isovalues, r.budget, eps);
  }
  st.eps_used = eps;
  const Context c = MakeContext(h, xf, r, eps);

  auto t0 = std::chrono::steady_clock::now();
  extract_internal::SplitTree top;
  const std::vector<Node> items = SplitIntoSubtrees(c, nullptr, retain ? &top : nullptr);
  st.split_ms = Ms(t0);
  st.subtrees = int(items.size());

  // Extract every subtree into its own buffers, in parallel. As soon as a prefix of subtrees
  // (in draw order) is complete it is appended to the result under a lock, so an observer can
  // ship the farthest triangles while the nearer ones are still being extracted. Appending in
  // order also settles vertex sharing across subtrees: a vertex on a subtree's boundary faces
  // is looked up by edge key, and the first occurrence in draw order keeps its index.
  t0 = std::chrono::steady_clock::now();
  std::vector<std::unique_ptr<SubtreeMesh>> parts(items.size());
  SubtreeMeshPool& pool = SubtreeMeshPool::Global();
  std::vector<char> done(items.size(), 0);
  size_t next = 0;
  std::mutex mu;
  // Edge key -> frame vertex of the boundary vertices appended so far: a flat table, where a
  // node-based map spent a malloc and a free per boundary vertex inside the serial join.
  EdgeVertexTable boundary_ids(size_t{1} << 16);
  ClipVertexIds clipped_ids;  // the same for vertices made by clipping at the data box
  std::vector<uint32_t> to_global;
  std::atomic<bool> halted{false};                 // cancelled, or past the deadline (StopReason)
  std::atomic<bool> recording{retain != nullptr};  // false: the cut was refused room
  OrderedMesh& m = result.mesh;
  if (r.budget > 0) {
    // Reserving the frame's size up front saves growing the arrays by doubling, which would
    // copy what the join already copied (~1/3 of the join's time at 1 M triangles). The budget
    // search counted the frame at the chosen eps (clipping at the data box included); sizing
    // from that count, not the budget, keeps a large budget from
    // reserving hundreds of MB of address space for a small frame. An eps from the memo comes
    // with no count: the budget bounds the frame then. Isosurface meshes have about half as
    // many vertices as triangles.
    const size_t t = size_t(std::min<int64_t>(counted.value_or(r.budget), int64_t{1} << 24));
    m.triangles.reserve(3 * t);
    m.surface.reserve(t);
    m.positions.reserve(3 * (t / 2 + 1024));
    m.normals.reserve(3 * (t / 2 + 1024));
  }
  double join_ms = 0;
  size_t appended = 0;  // parts

  if (retain) {
    // Each subtree records into its own part; the parts keep their buffers across frames.
    retain->parts_.resize(items.size());
    for (extract_internal::CutPart& part : retain->parts_) part.clear();
    retain->part_first_triangle_.assign(items.size(), 0);
  }
  // Without a reservation (an eps request) the arrays would grow by doubling, ~9 times from
  // the first part to a 1 M-triangle frame, copying about the frame once more. Once a 16th of
  // the parts is in (parts vary ~10x in size: fewer project badly), they grow instead to what
  // the parts so far project for the whole frame, plus a quarter (at least 1.5x): one or two
  // more steps.
  auto make_room = [&](auto& v, size_t more) {
    const size_t needed = v.size() + more;
    if (needed <= v.capacity()) return;
    size_t grown = std::max(needed, 2 * v.capacity());
    if (16 * appended >= items.size()) {
      const size_t projected = needed * items.size() / (appended + 1);
      grown = std::max({needed, projected + projected / 4, v.capacity() + v.capacity() / 2});
    }
    v.reserve(grown);
  };

  auto append = [&](SubtreeMesh& part) {
    const auto tj = std::chrono::steady_clock::now();
    const size_t part_vertices = part.vertex_count();
    make_room(m.positions, 3 * part_vertices);
    make_room(m.normals, 3 * part_vertices);
    make_room(m.triangles, part.triangles.size());
    make_room(m.surface, part.surface.size());
    // A boundary vertex already appended by an earlier part (in draw order) is reused and the
    // part's own copy dropped; the others are copied and get compacted indices.
    constexpr uint32_t kUnset = EdgeVertexTable::kMissing;
    to_global.assign(part_vertices, kUnset);
    for (const auto& [local, key] : part.boundary) to_global[local] = boundary_ids.Find(key);
    for (const auto& [local, key] : part.clipped) {
      const auto found = clipped_ids.find(key);
      if (found != clipped_ids.end()) to_global[local] = found->second;
    }
    // Owned vertices are copied in runs between the (few) reused ones.
    size_t out = m.vertex_count();
    const float* pos = part.positions.data();
    const float* nrm = part.normals.data();
    for (size_t v = 0; v < part_vertices;) {
      if (to_global[v] != kUnset) {
        ++v;
        continue;
      }
      size_t end = v;
      while (end < part_vertices && to_global[end] == kUnset) to_global[end++] = uint32_t(out++);
      m.positions.insert(m.positions.end(), pos + 3 * v, pos + 3 * end);
      m.normals.insert(m.normals.end(), nrm + 3 * v, nrm + 3 * end);
      v = end;
    }
    for (const auto& [local, key] : part.boundary) boundary_ids.FindOrInsert(key, to_global[local]);
    for (const auto& [local, key] : part.clipped) clipped_ids.try_emplace(key, to_global[local]);
    const size_t first = m.triangle_count();
    const size_t tri_base = m.triangles.size();
    m.triangles.insert(m.triangles.end(), part.triangles.data(),
                       part.triangles.data() + part.triangles.size());
    for (auto it = m.triangles.begin() + tri_base; it != m.triangles.end(); ++it)
      *it = to_global[*it];
    m.surface.insert(m.surface.end(), part.surface.data(),
                     part.surface.data() + part.surface.size());
    if (retain) retain->part_first_triangle_[appended] = uint32_t(first);
    ++appended;
    st.tets_visited += part.visited;
    st.leaves += part.leaves;
    join_ms += Ms(tj);
    if (observer && observer->on_ready) observer->on_ready(m, first, m.triangle_count());
  };

  const bool gradients = extract_internal::NeedsGradients(c, false);
  const bool recorded_gradients = extract_internal::NeedsGradients(c, true);
  arena.execute([&] {
    // Workers take subtrees in draw order from a shared counter (not halves of the range, as
    // parallel_for would), so the appended prefix grows steadily: appending overlaps
    // extraction and the first triangles are ready early.
    std::atomic<size_t> next_item{0};
    const int workers = tbb::this_task_arena::max_concurrency();
    tbb::parallel_for(
        0, workers,
        [&](int) {
          // One table per worker thread, kept across frames (TBB's threads persist).
          static thread_local EdgeVertexTable table(1 << 14);
          for (size_t i = next_item++; i < items.size(); i = next_item++) {
            if (observer && !StopReason(observer).ok()) {
              halted = true;
              return;
            }
            std::unique_ptr<SubtreeMesh> part = pool.Acquire();
            if (retain && recording.load(std::memory_order_relaxed)) {
              extract_internal::CutPart& records = retain->parts_[i];
              const size_t before = records.capacity_bytes();
              if (recorded_gradients)
                Traverser<true, true>(c, &table, part.get(), nullptr, &records).Run(items[i]);
              else
                Traverser<true, true, false>(c, &table, part.get(), nullptr, &records)
                    .Run(items[i]);
              // Each part's growth is asked for as it happens, so the recording never holds
              // more than it was granted plus what its workers are recording at the moment.
              const size_t after = records.capacity_bytes();
              if (after > before && retain->reserve_ && !retain->reserve_(int64_t(after - before)))
                recording = false;
            } else if (gradients) {
              Traverser<true>(c, &table, part.get()).Run(items[i]);
            } else {
              Traverser<true, false, false>(c, &table, part.get()).Run(items[i]);
            }
            if (part->maybe_unused) part->DropUnusedVertices();
            std::lock_guard<std::mutex> lock(mu);
            parts[i] = std::move(part);
            done[i] = 1;
            while (next < items.size() && done[next] && !halted) {
              append(*parts[next]);
              pool.Release(std::move(parts[next++]));
            }
          }
        },
        tbb::simple_partitioner());
  });
  if (halted) {
    if (retain) retain->Clear();
    return StopReason(observer);
  }
  st.extract_ms = Ms(t0) - join_ms;
  st.join_ms = join_ms;

  st.triangles = int64_t(m.triangle_count());
  st.vertices = int64_t(m.vertex_count());
  for (uint8_t s : m.surface) ++st.triangles_per_surface[s];
  if (retain && !recording) retain->Release();
  if (retain && recording) {
    RetainedCut& cut = *retain;
    top.Record(&cut.top_, cut.root_begin_.data(), cut.root_end_.data());
    cut.name_ = MeshName::Of(r);
    cut.eps_ = eps;
    cut.k_ = h.k();
    cut.xf_ = xf;
    cut.iso_count_ = c.iso_count;
    std::copy(c.iso, c.iso + c.iso_count, cut.iso_);
    cut.leaves_ = st.leaves;
    cut.pending_triangles_ = m.triangle_count();  // the caller keeps the mesh (KeepMesh)
    cut.pending_vertices_ = m.vertex_count();
  }
  st.total_ms = Ms(t_start);
  return result;
}

}  // namespace isostream
