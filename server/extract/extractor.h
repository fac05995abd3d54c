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
  // of its threads) with increasing ranges; copy what you need and return quickly.
  std::function<void(const OrderedMesh& mesh, size_t first, size_t end)> on_ready;
  // Checked between subtrees (of the budget search's counting passes too): once true, the
  // extraction stops and returns CANCELLED; once past `deadline`, DEADLINE_EXCEEDED.
  const std::atomic<bool>* cancel = nullptr;
  std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
};

// The one-call form. `xf` places the hierarchy cube in world space (volume spacing, origin).
absl::StatusOr<ExtractResult> Extract(const Hierarchy& hierarchy, const GridToWorld& xf,
                                      const ExtractRequest& request,
                                      const ExtractObserver* observer = nullptr);

// Triangle count at a given eps without building the mesh; stops counting past `limit` and
// then returns limit + 1.
// Used by the budget search; exposed for tests and benchmarks.
absl::StatusOr<int64_t> CountTriangles(const Hierarchy& hierarchy, const GridToWorld& xf,
                                       const ExtractRequest& request, double eps,
                                       int64_t limit = INT64_MAX);

// The triangle count as a function of eps, from one counting pass: element i is the count at
// the eps of eta code first_code + i (the float with bits code << 16; etas are stored as such
// codes, so the count only changes at them and is constant between). Codes run to
// last_code <= 0x7f80 (+inf). What the budget search reads; exposed for tests and tools.
absl::StatusOr<std::vector<int64_t>> CountTrianglesPerEtaCode(const Hierarchy& hierarchy,
                                                              const GridToWorld& xf,
                                                              const ExtractRequest& request,
                                                              uint32_t first_code,
                                                              uint32_t last_code);

}  // namespace isostream
