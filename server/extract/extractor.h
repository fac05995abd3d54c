// Adaptive extraction of multiple transparent isosurfaces from the bisection hierarchy, with
// triangles emitted in back-to-front order for a view (Gerstner §3-§5).
//
// Contract: Extract() returns an OrderedMesh whose triangles, drawn first to last, form a
// valid painter's order for request.view (perspective eye anywhere, inside the volume too, or
// orthographic direction). The mesh is crack-free for every eps (saturated eta), its field
// differs from the full-resolution one by less than eps in data units, and the output is the
// same for any thread count. Cost follows the output: subtrees no isovalue can meet are skipped.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <vector>

#include "server/extract/extract_request.h"
#include "server/hierarchy/hierarchy.h"
#include "shared/ordered_mesh.h"
#include "shared/status.h"

namespace isostream {

struct ExtractResult {
  OrderedMesh mesh;
  ExtractStats stats;
};

// Watches an extraction as it runs, for streaming and for cancelling.
struct ExtractObserver {
  // Called as the mesh grows, in draw order: triangles [first, end) of `mesh`, and every
  // vertex they use, are final. Calls come one at a time (under the extractor's lock, on one
  // of its threads) with increasing ranges; copy what you need and return quickly: never wait
  // here (for a client, say), as every worker of the extraction waits for this lock in turn.
  std::function<void(const OrderedMesh& mesh, size_t first, size_t end)> on_ready;
  // Checked between subtrees (of the budget search's counting passes too): once true, the
  // extraction stops and returns CANCELLED; once past `deadline`, DEADLINE_EXCEEDED.
  const std::atomic<bool>* cancel = nullptr;
  std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
};

class RetainedCut;

// The one-call form. `xf` places the hierarchy cube in world space (volume spacing, origin).
// With `retain`, the frame is also kept there for other views (retained_cut.h).
absl::StatusOr<ExtractResult> Extract(const Hierarchy& hierarchy, const GridToWorld& xf,
                                      const ExtractRequest& request,
                                      const ExtractObserver* observer = nullptr,
                                      RetainedCut* retain = nullptr);

// Triangle count at a given eps without building the mesh; stops counting past `limit` and
// then returns limit + 1.
// Used by the budget search; exposed for tests and benchmarks.
absl::StatusOr<int64_t> CountTriangles(const Hierarchy& hierarchy, const GridToWorld& xf,
                                       const ExtractRequest& request, double eps,
                                       int64_t limit = INT64_MAX);

// Etas are stored as 16-bit codes, the top half of a float: code k stands for the eps whose
// float has bits k << 16, and a node stops where its eta is below eps, so the triangle count
// changes only at codes and is constant between them.
inline constexpr uint32_t kInfiniteEtaCode = 0x7f80;  // +inf
inline constexpr uint32_t kEtaCodesPerOctave = 128;   // 7 mantissa bits
// The eps of `code`; the +inf code as the largest float (which stops the same etas: every
// finite one) so that it stays finite.
double EtaCodeEps(uint32_t code);
// The smallest code whose eps is >= eps (eps >= 0).
uint32_t EtaCodeAtLeast(double eps);
// One code above the hierarchy's largest eta (its root's, saturated): nothing refines there,
// so its count is the coarsest mesh's.
uint32_t CoarsestEtaCode(const Hierarchy& hierarchy);

// The triangle count as a function of eps, from one counting pass: element i is the count at
// the eps of code first_code + i, for codes up to last_code <= kInfiniteEtaCode. What the
// budget search reads; exposed for tests and tools.
absl::StatusOr<std::vector<int64_t>> CountTrianglesPerEtaCode(const Hierarchy& hierarchy,
                                                              const GridToWorld& xf,
                                                              const ExtractRequest& request,
                                                              uint32_t first_code,
                                                              uint32_t last_code);

}  // namespace isostream
