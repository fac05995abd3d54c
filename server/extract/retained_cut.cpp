#include "server/extract/retained_cut.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <glm/geometric.hpp>
#include <numeric>
#include <string>

#include "server/extract/view_context.h"

namespace isostream {

using extract_internal::ChildZeroFirst;
using extract_internal::Context;
using extract_internal::CutComponent;
using extract_internal::CutRecord;
using extract_internal::MultiLeaf;
using extract_internal::Unpack;

bool RetainedCut::Serves(const ExtractRequest& r, double budget_eps) const {
  if (mesh_.empty() && cut_.records.size() == 0 && isovalues_.empty()) return false;
  if (r.isovalues != isovalues_ || r.normals != normals_) return false;
  if (r.budget > 0) return r.budget == budget_ || (budget_eps >= 0 && budget_eps == eps_);
  return budget_ == 0 && r.eps == eps_;
}

size_t RetainedCut::memory_bytes() const {
  return (mesh_.positions.capacity() + mesh_.normals.capacity()) * sizeof(float) +
         mesh_.triangles.capacity() * sizeof(uint32_t) + mesh_.surface.capacity() +
         cut_.records.capacity() * sizeof(CutRecord) + cut_.multi.capacity() * sizeof(MultiLeaf) +
         cut_.components.capacity() * sizeof(CutComponent);
}

namespace {

// Appends what one walk of the records draws, far to near, to `out`.
class Walker {
 public:
  Walker(const Context& c, const extract_internal::CutPart& cut, const OrderedMesh& from,
         OrderedMesh* out)
      : c_(c), cut_(cut), from_(from), out_(out) {}

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
          const bool swap = ChildZeroFirst(c_, r.cls, r.a) != r.child0_drawn_first;
          stack[top++] = swap ? first : second;
          cur = swap ? second : first;
          continue;
        }
        if (r.kind == CutRecord::kLeaf) {
          Triangles(uint32_t(r.a), r.b);
        } else {
          MultiLeafTriangles(cut_.multi[r.a]);
        }
      }
      if (top == 0) return;
      cur = stack[--top];
    }
  }

  int64_t walked() const { return walked_; }
  // Triangles drawn so far: out's arrays are sized for all of them up front.
  size_t written() const { return written_; }

 private:
  // A leaf holds one or two triangles mostly: a plain loop, where vector inserts cost a call
  // and their checks per leaf (2.5x the whole walk's time).
  void Triangles(uint32_t first, uint32_t count) {
    const uint32_t* from = from_.triangles.data() + 3 * size_t(first);
    uint32_t* to = out_->triangles.data() + 3 * written_;
    for (uint32_t i = 0; i < 3 * count; ++i) to[i] = from[i];
    const uint8_t* from_surface = from_.surface.data() + first;
    uint8_t* to_surface = out_->surface.data() + written_;
    for (uint32_t i = 0; i < count; ++i) to_surface[i] = from_surface[i];
    written_ += count;
  }

  // Components far to near, as LeafEmitter::Components orders them.
  void MultiLeafTriangles(const MultiLeaf& leaf) {
    const CutComponent* comp = &cut_.components[leaf.first];
    const int count = int(leaf.count);
    const int first = int(comp[0].iso);  // components hold consecutive isovalues
    const int last = first + count;
    auto draw = [&](int iso) {
      const CutComponent& k = comp[iso - first];
      Triangles(k.first_triangle, k.triangles);
    };
    if (!c_.ordered) {
      for (int i = first; i < last; ++i) draw(i);
    } else if (c_.orthographic) {
      const bool descending = glm::dot(leaf.g, c_.dir) > 0;
      for (int i = first; i < last; ++i) draw(descending ? last - 1 - (i - first) : i);
    } else {
      const double fe = leaf.f0 + glm::dot(leaf.g, c_.eye - glm::dvec3(Unpack(leaf.v0)));
      int split = first;
      while (split < last && c_.iso[split] <= fe) ++split;
      for (int i = last - 1; i >= split; --i) draw(i);
      for (int i = first; i < split; ++i) draw(i);
    }
  }

  const Context& c_;
  const extract_internal::CutPart& cut_;
  const OrderedMesh& from_;
  OrderedMesh* out_;
  int64_t walked_ = 0;
  size_t written_ = 0;
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
  const OrderedMesh& from = cut.mesh_;
  m.positions = from.positions;
  m.normals = from.normals;
  m.triangles.resize(from.triangles.size());
  m.surface.resize(from.surface.size());

  int roots[kNumInitialTets];
  if (c.ordered) {
    const double size = double(1 << c.k);
    ReferenceTets::Get().InitialOrder(c.orthographic ? c.dir : c.eye / size, c.orthographic,
                                      roots);
  } else {
    std::iota(roots, roots + kNumInitialTets, 0);
  }
  Walker walker(c, cut.cut_, from, &m);
  for (int i : roots) {
    if (observer) {
      if (observer->cancel && observer->cancel->load(std::memory_order_relaxed))
        return absl::CancelledError("extraction cancelled");
      if (std::chrono::steady_clock::now() > observer->deadline)
        return absl::DeadlineExceededError("extraction passed its deadline");
    }
    const size_t first = walker.written();
    walker.Subtree(cut.root_begin_[i], cut.root_end_[i]);
    if (observer && observer->on_ready && walker.written() > first)
      observer->on_ready(m, first, walker.written());
  }
  if (walker.written() != from.triangle_count())
    return absl::InternalError("retained cut drew " + std::to_string(walker.written()) + " of " +
                               std::to_string(from.triangle_count()) + " triangles");

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
