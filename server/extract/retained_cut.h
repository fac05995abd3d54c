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
#include <functional>
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
  size_t triangle_count() const { return mesh_.triangle_count(); }
  size_t memory_bytes() const;
  // True until a recorded frame has its mesh kept (KeepMesh).
  bool empty() const { return name_.isovalues.empty() || pending_triangles_ != kNoneRecorded; }
  // Extract records the frame's tree but leaves its triangles with the caller, who streams
  // them meanwhile: the cut serves other views once the caller hands that frame back here,
  // unchanged (moved, not copied: a copy cost ~25 MB of memory traffic per 1 M triangles).
  // Returns false, the cut cleared, for a frame other than the one just recorded.
  bool KeepMesh(OrderedMesh&& frame);
  // Empties it, keeping its tree's buffers for the next frame recorded into it (fresh ones
  // cost a page fault per 4 KiB); the mesh's are freed (the next one is moved in).
  void Clear();
  // Empties it and frees every buffer.
  void Release();
  // What its tree's buffers hold (memory_bytes without the mesh).
  size_t tree_bytes() const;

  // Asked, from the extraction's worker threads, for each `bytes` the recording's buffers grow
  // by, as they grow (once per subtree of the split): false stops the recording (the frame is
  // still extracted, and the cut released). Unset: every growth is granted.
  using ReserveFn = std::function<bool(int64_t bytes)>;
  void SetReserve(ReserveFn reserve) { reserve_ = std::move(reserve); }

 private:
  friend absl::StatusOr<ExtractResult> Extract(const Hierarchy&, const GridToWorld&,
                                               const ExtractRequest&, const ExtractObserver*,
                                               RetainedCut*);
  friend absl::StatusOr<ExtractResult> Reorder(const RetainedCut&, const View&, DrawOrder,
                                               const ExtractObserver*);

  // What the mesh was extracted for, and at.
  MeshName name_;
  double eps_ = 0;
  int k_ = 0;
  GridToWorld xf_;
  float iso_[kMaxSurfaces] = {};  // sorted, as the traversal's Context holds them
  int iso_count_ = 0;

  OrderedMesh mesh_;  // the frame, in the extraction's order
  // Triangles of the frame recorded but not yet kept (KeepMesh), or kNoneRecorded.
  static constexpr size_t kNoneRecorded = ~size_t{0};
  size_t pending_triangles_ = kNoneRecorded;
  size_t pending_vertices_ = 0;
  // The tree above the split's subtrees (kPart records stand for them), and the subtrees',
  // with the frame triangle each one's numbers start from.
  extract_internal::CutPart top_;
  std::vector<extract_internal::CutPart> parts_;
  std::vector<uint32_t> part_first_triangle_;
  // Records of initial tetrahedron i in top_: [root_begin_[i], root_end_[i]).
  std::array<uint32_t, kNumInitialTets> root_begin_{}, root_end_{};
  int64_t leaves_ = 0;
  ReserveFn reserve_;
};

// The cut's mesh drawn for `view` in `order`: the same result as Extract for that view (stats:
// eps, counts; tets_visited counts the records walked). `observer` as for Extract.
absl::StatusOr<ExtractResult> Reorder(const RetainedCut& cut, const View& view,
                                      DrawOrder order = DrawOrder::kBackToFront,
                                      const ExtractObserver* observer = nullptr);

}  // namespace isostream
