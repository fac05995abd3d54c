#include "server/extract/retained_cut.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <functional>
#include <glm/geometric.hpp>
#include <numeric>
#include <string>

#include "server/extract/view_context.h"

namespace isostream {

using extract_internal::ChildZeroFirst;
using extract_internal::Context;
using extract_internal::CutRecord;
using extract_internal::MultiLeaf;
using extract_internal::Unpack;

bool RetainedCut::Serves(const ExtractRequest& r, double budget_eps) const {
  if (empty()) return false;
  if (r.isovalues != isovalues_ || r.normals != normal_mode_) return false;
  if (r.budget > 0) return r.budget == budget_ || (budget_eps >= 0 && budget_eps == eps_);
  return budget_ == 0 && r.eps == eps_;
}

size_t RetainedCut::memory_bytes() const {
  return (positions_.capacity() + normals_.capacity()) * sizeof(float) +
         cut_.records.capacity() * sizeof(CutRecord) + cut_.multi.capacity() * sizeof(MultiLeaf);
}

namespace {

// Writes what one walk of the records draws, far to near, into `out` (sized for the frame).
class Walker {
 public:
  // `ready` (may be empty) hears of drawn prefixes every `ready_step` triangles or so.
  Walker(const Context& c, const extract_internal::CutPart& cut, OrderedMesh* out,
         const std::function<void(const OrderedMesh&, size_t, size_t)>* ready, size_t ready_step)
      : c_(c), cut_(cut), out_(out), ready_(ready), ready_step_(ready_step) {}

  // Reports triangles drawn since the last report.
  void Report() {
    if (ready_ && *ready_ && written_ > reported_) (*ready_)(*out_, reported_, written_);
    reported_ = written_;
  }

  // The subtree in records [begin, end).
  void Subtree(uint32_t begin, uint32_t end) {
    struct Range {
      uint32_t begin, end;
    };
    Range stack[3 * 16 + 8];  // one per refined ancestor
    int top = 0;
    Range cur{begin, end};
    for (;;) {
      if (cur.begin < cur.end) {
        ++walked_;
        const CutRecord& r = cut_.records[cur.begin];
        if (r.kind == CutRecord::kRefine) {
          const Range first{cur.begin + 1, r.b}, second{r.b, cur.end};
          // The test the traversal makes, so the order is a fresh extraction's.
          const bool swap = ChildZeroFirst(c_, TetClass{r.c}, r.a) != r.child0_drawn_first;
          stack[top++] = swap ? first : second;
          cur = swap ? second : first;
          continue;
        }
        if (r.kind == CutRecord::kLeaf) {
          Triangles(&r + 1, r.b);
        } else {
          MultiLeafTriangles(r);
        }
        if (written_ - reported_ >= ready_step_) Report();
      }
      if (top == 0) return;
      cur = stack[--top];
    }
  }

  int64_t walked() const { return walked_; }
  size_t written() const { return written_; }

 private:
  void Triangles(const CutRecord* from, uint32_t count) {
    uint32_t* to = out_->triangles.data() + 3 * written_;
    uint8_t* surface = out_->surface.data() + written_;
    for (uint32_t t = 0; t < count; ++t) {
      to[3 * t] = uint32_t(from[t].a);
      to[3 * t + 1] = uint32_t(from[t].a >> 32);
      to[3 * t + 2] = from[t].b;
      surface[t] = from[t].c;
    }
    written_ += count;
  }

  // Components far to near, as LeafEmitter::Components orders them. They follow the leaf's
  // record by ascending isovalue, each a kComponent record and its triangles.
  void MultiLeafTriangles(const CutRecord& leaf_record) {
    const MultiLeaf& leaf = cut_.multi[leaf_record.a];
    const CutRecord* block[kMaxSurfaces];
    const int count = int(leaf_record.b);
    const CutRecord* at = &leaf_record + 1;
    for (int i = 0; i < count; ++i, at += 1 + at->b) block[i] = at;
    // Components without triangles were not recorded: block order is isovalue order all the
    // same, and only the split below needs the isovalues themselves.
    auto draw = [&](int i) { Triangles(block[i] + 1, block[i]->b); };
    if (!c_.ordered) {
      for (int i = 0; i < count; ++i) draw(i);
    } else if (c_.orthographic) {
      const bool descending = glm::dot(leaf.g, c_.dir) > 0;
      for (int i = 0; i < count; ++i) draw(descending ? count - 1 - i : i);
    } else {
      const double fe = leaf.f0 + glm::dot(leaf.g, c_.eye - glm::dvec3(Unpack(leaf.v0)));
      int split = 0;
      while (split < count && c_.iso[block[split]->c] <= fe) ++split;
      for (int i = count - 1; i >= split; --i) draw(i);
      for (int i = 0; i < split; ++i) draw(i);
    }
  }

  const Context& c_;
  const extract_internal::CutPart& cut_;
  OrderedMesh* out_;
  const std::function<void(const OrderedMesh&, size_t, size_t)>* ready_;
  const size_t ready_step_;
  int64_t walked_ = 0;
  size_t written_ = 0, reported_ = 0;
};

}  // namespace

absl::StatusOr<ExtractResult> Reorder(const RetainedCut& cut, const View& view, DrawOrder order,
                                      const ExtractObserver* observer) {
  const auto t_start = std::chrono::steady_clock::now();
  if (cut.isovalues_.empty()) return absl::FailedPreconditionError("no frame retained");
  ExtractRequest check;
  check.isovalues = cut.isovalues_;
  check.eps = cut.eps_;
  check.view = view;
  check.order = order;
  ISOSTREAM_RETURN_IF_ERROR(ValidateRequest(check));

  Context c;
  c.k = cut.k_;
  c.iso_count = cut.iso_count_;
  std::copy(cut.iso_, cut.iso_ + cut.iso_count_, c.iso);
  extract_internal::SetView(&c, cut.xf_, view, order);

  ExtractResult result;
  OrderedMesh& m = result.mesh;
  m.positions = cut.positions_;
  m.normals = cut.normals_;
  m.triangles.resize(3 * cut.triangles_);
  m.surface.resize(cut.triangles_);

  int roots[kNumInitialTets];
  if (c.ordered) {
    const double size = double(1 << c.k);
    ReferenceTets::Get().InitialOrder(c.orthographic ? c.dir : c.eye / size, c.orthographic,
                                      roots);
  } else {
    std::iota(roots, roots + kNumInitialTets, 0);
  }
  // Prefixes are reported every few thousand triangles, as the extraction's subtrees report
  // them, so the first chunk can leave early; stopping is checked per initial tetrahedron
  // (a whole frame is drawn in tens of milliseconds).
  Walker walker(c, cut.cut_, &m, observer ? &observer->on_ready : nullptr, 4096);
  for (int i : roots) {
    if (observer) {
      if (observer->cancel && observer->cancel->load(std::memory_order_relaxed))
        return absl::CancelledError("extraction cancelled");
      if (std::chrono::steady_clock::now() > observer->deadline)
        return absl::DeadlineExceededError("extraction passed its deadline");
    }
    walker.Subtree(cut.root_begin_[i], cut.root_end_[i]);
  }
  walker.Report();
  if (walker.written() != cut.triangles_)
    return absl::InternalError("retained cut drew " + std::to_string(walker.written()) + " of " +
                               std::to_string(cut.triangles_) + " triangles");

  ExtractStats& st = result.stats;
  st.eps_used = cut.eps_;
  st.triangles = int64_t(m.triangle_count());
  st.vertices = int64_t(m.vertex_count());
  for (uint8_t s : m.surface) ++st.triangles_per_surface[s];
  st.tets_visited = walker.walked();
  st.leaves = cut.leaves_;
  st.reordered = true;
  st.total_ms = st.extract_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_start)
          .count();
  return result;
}

}  // namespace isostream
