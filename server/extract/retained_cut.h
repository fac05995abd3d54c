// A frame kept so that the next view is served by re-ordering it instead of extracting again.
//
// The adaptive mesh depends on the volume, the isovalues, eps and the normal mode; only its
// order depends on the view (Gerstner §4). Rotating the view is what users do most, so a
// session keeps its last frame's cut: the triangles and vertices, and the part of the tree
// that orders them (the refined nodes, in preorder, and the leaves). Reorder walks it with the
// new view's plane tests: the triangles come out exactly as a fresh extraction for that view
// would draw them (same triangles, vertices, surfaces and order; vertex numbers may differ), at
// the cost of a walk and a copy instead of a traversal of the hierarchy.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "server/extract/cut_recorder.h"
#include "server/extract/extract_request.h"
#include "server/extract/extractor.h"

namespace isostream {

class RetainedCut {
 public:
  // Whether `request` asks for this cut's mesh (in any view and order): same isovalues in the
  // same order, normal mode, and eps (or a budget whose remembered eps, when `budget_eps` is
  // given, is this cut's).
  bool Serves(const ExtractRequest& request, double budget_eps = -1) const;

  double eps_used() const { return eps_; }
  size_t triangle_count() const { return triangles_; }
  size_t memory_bytes() const;
  bool empty() const { return isovalues_.empty(); }

 private:
  friend absl::StatusOr<ExtractResult> Extract(const Hierarchy&, const GridToWorld&,
                                               const ExtractRequest&, const ExtractObserver*,
                                               RetainedCut*);
  friend absl::StatusOr<ExtractResult> Reorder(const RetainedCut&, const View&, DrawOrder,
                                               const ExtractObserver*);

  // What the mesh was extracted with.
  std::vector<float> isovalues_;
  double eps_ = 0;
  int64_t budget_ = 0;
  NormalMode normal_mode_ = NormalMode::kSmooth;
  int k_ = 0;
  GridToWorld xf_;
  float iso_[kMaxSurfaces] = {};  // sorted, as the traversal's Context holds them
  int iso_count_ = 0;

  std::vector<float> positions_, normals_;  // the frame's vertices, as OrderedMesh holds them
  size_t triangles_ = 0;
  extract_internal::CutPart cut_;  // one subtree per initial tetrahedron, triangles inside
  // Records of initial tetrahedron i: [root_begin_[i], root_end_[i]).
  std::array<uint32_t, kNumInitialTets> root_begin_{}, root_end_{};
  int64_t leaves_ = 0;
};

// The cut's mesh drawn for `view` in `order`: the same result as Extract for that view (stats:
// eps, counts; tets_visited counts the records walked). `observer` as for Extract.
absl::StatusOr<ExtractResult> Reorder(const RetainedCut& cut, const View& view,
                                      DrawOrder order = DrawOrder::kBackToFront,
                                      const ExtractObserver* observer = nullptr);

}  // namespace isostream
