#include "server/extract/retained_cut.h"

#include <algorithm>
#include <chrono>
#include <glm/geometric.hpp>
#include <numeric>
#include <string>

#include "server/extract/view_context.h"

namespace isostream {

using extract_internal::Context;
using extract_internal::CutRecord;
using extract_internal::MultiLeaf;

bool RetainedCut::Serves(const ExtractRequest& r, double budget_eps) const {
  if (empty()) return false;
  const MeshName asked = MeshName::Of(r);
  if (asked == name_) return true;
  // A budget whose remembered eps is the one this cut was drawn at asks for the same mesh.
  return r.budget > 0 && budget_eps >= 0 && budget_eps == eps_ &&
         asked.isovalues == name_.isovalues && asked.normals == name_.normals;
}

bool RetainedCut::KeepMesh(OrderedMesh&& frame) {
  const bool recorded = pending_triangles_ == frame.triangle_count() &&
                        pending_vertices_ == frame.vertex_count() && !name_.isovalues.empty();
  if (!recorded) {
    Clear();
    return false;
  }
  mesh_ = std::move(frame);
  pending_triangles_ = kNoneRecorded;
  return true;
}

void RetainedCut::Clear() {
  name_ = MeshName();
  pending_triangles_ = kNoneRecorded;
  eps_ = 0;
  iso_count_ = 0;
  mesh_ = OrderedMesh();  // the next frame's mesh is moved in, not copied into these
  top_.clear();
  for (extract_internal::CutPart& part : parts_) part.clear();
  part_first_triangle_.clear();
  root_begin_.fill(0);
  root_end_.fill(0);
  leaves_ = 0;
}

void RetainedCut::Release() {
  ReserveFn reserve = std::move(reserve_);
  *this = RetainedCut();
  reserve_ = std::move(reserve);
}

size_t RetainedCut::tree_bytes() const {
  size_t bytes = top_.capacity_bytes() + part_first_triangle_.capacity() * sizeof(uint32_t);
  for (const extract_internal::CutPart& part : parts_) bytes += part.capacity_bytes();
  return bytes;
}

size_t RetainedCut::memory_bytes() const {
  return tree_bytes() + (mesh_.positions.capacity() + mesh_.normals.capacity()) * sizeof(float) +
         mesh_.triangles.capacity() * sizeof(uint32_t) + mesh_.surface.capacity();
}

namespace {

// What a walk reads of a RetainedCut besides the top records.
struct RetainedCutParts {
  const OrderedMesh& mesh;
  const std::vector<extract_internal::CutPart>& parts;
  const std::vector<uint32_t>& first_triangle;
};

// Writes what one walk of the records draws, far to near, into `out` (sized for the frame).
class Walker {
 public:
  // `observer` (may be null) hears of drawn prefixes every `ready_step` triangles or so, and
  // can stop the walk at each of them.
  Walker(const Context& c, const RetainedCutParts& cut, OrderedMesh* out,
         const ExtractObserver* observer, size_t ready_step)
      : c_(c), cut_(cut), out_(out), observer_(observer), ready_step_(ready_step) {}

  // The subtree in records [begin, end) of `part`, whose triangle numbers start at `base`.
  void Subtree(const extract_internal::CutPart& part, uint32_t base, uint32_t begin, uint32_t end) {
    struct Range {
      uint32_t begin, end;
    };
    Range stack[3 * 16 + 8];  // one per refined ancestor
    int top = 0;
    Range cur{begin, end};
    const CutRecord* records = part.records.data();
    for (;;) {
      if (cur.begin < cur.end) {
        ++walked_;
        const CutRecord& r = records[cur.begin];
        if (r.kind == CutRecord::kRefine) {
          const Range first{cur.begin + 1, r.b}, second{r.b, cur.end};
          // The test the traversal makes, so the order is a fresh extraction's.
          const bool swap = extract_internal::ChildZeroFirstAtSide(
                                c_, TetClass{r.c}, int64_t(r.a)) != r.child0_drawn_first;
          stack[top++] = swap ? first : second;
          cur = swap ? second : first;
          continue;
        }
        if (r.kind == CutRecord::kLeaf) {
          Triangles(base + uint32_t(r.a), r.b);
        } else if (r.kind == CutRecord::kMultiLeaf) {
          MultiLeafTriangles(part, base, r);
        } else {  // kPart: a subtree of the split, in its own records
          const extract_internal::CutPart& sub = cut_.parts[r.a];
          Subtree(sub, cut_.first_triangle[r.a], 0, uint32_t(sub.records.size()));
          if (!stop_.ok()) return;
        }
        if (written_ - reported_ >= ready_step_) {
          Report();
          if (!stop_.ok()) return;
        }
      }
      if (top == 0) return;
      cur = stack[--top];
    }
  }

  // Reports triangles drawn since the last report, and whether the observer stops the walk
  // (cancelled, or past its deadline: stop()).
  void Report() {
    if (observer_ == nullptr) return;
    if (observer_->on_ready && written_ > reported_)
      observer_->on_ready(*out_, reported_, written_);
    reported_ = written_;
    if (observer_->cancel && observer_->cancel->load(std::memory_order_relaxed))
      stop_ = absl::CancelledError("extraction cancelled");
    else if (std::chrono::steady_clock::now() > observer_->deadline)
      stop_ = absl::DeadlineExceededError("extraction passed its deadline");
  }
  const absl::Status& stop() const { return stop_; }

  int64_t walked() const { return walked_; }
  size_t written() const { return written_; }

 private:
  // A leaf holds one or two triangles mostly: a plain loop, where vector inserts cost a call
  // and their checks per leaf.
  void Triangles(uint32_t first, uint32_t count) {
    const uint32_t* from = cut_.mesh.triangles.data() + 3 * size_t(first);
    uint32_t* to = out_->triangles.data() + 3 * written_;
    for (uint32_t i = 0; i < 3 * count; ++i) to[i] = from[i];
    const uint8_t* from_surface = cut_.mesh.surface.data() + first;
    uint8_t* to_surface = out_->surface.data() + written_;
    for (uint32_t i = 0; i < count; ++i) to_surface[i] = from_surface[i];
    written_ += count;
  }

  // Components far to near, as LeafEmitter::Components orders them. Their records follow the
  // leaf's by ascending isovalue (those that left no triangle are not recorded: the order of
  // the others is the same).
  void MultiLeafTriangles(const extract_internal::CutPart& part, uint32_t base,
                          const CutRecord& leaf_record) {
    const MultiLeaf& leaf = part.multi[leaf_record.a];
    const CutRecord* comp = &leaf_record + 1;
    const int count = int(leaf_record.b);
    int order[kMaxSurfaces];
    extract_internal::ComponentOrder(
        c_, [&] { return leaf.g; }, leaf.f0, leaf.v0, [&](int i) { return c_.iso[comp[i].c]; },
        count, order);
    for (int j = 0; j < count; ++j) Triangles(base + uint32_t(comp[order[j]].a), comp[order[j]].b);
  }

  const Context& c_;
  const RetainedCutParts& cut_;
  OrderedMesh* out_;
  const ExtractObserver* observer_;
  const size_t ready_step_;
  absl::Status stop_;
  int64_t walked_ = 0;
  size_t written_ = 0, reported_ = 0;
};

}  // namespace

absl::StatusOr<ExtractResult> Reorder(const RetainedCut& cut, const View& view, DrawOrder order,
                                      const ExtractObserver* observer) {
  const auto t_start = std::chrono::steady_clock::now();
  if (cut.empty()) return absl::FailedPreconditionError("no frame retained");
  ExtractRequest check;
  check.isovalues = cut.name_.isovalues;
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
  m.positions = cut.mesh_.positions;
  m.normals = cut.mesh_.normals;
  m.triangles.resize(cut.mesh_.triangles.size());
  m.surface.resize(cut.mesh_.surface.size());

  int roots[kNumInitialTets];
  if (c.ordered) {
    const double size = double(1 << c.k);
    ReferenceTets::Get().InitialOrder(c.orthographic ? c.dir : c.eye / size, c.orthographic, roots);
  } else {
    std::iota(roots, roots + kNumInitialTets, 0);
  }
  // Prefixes are reported every few thousand triangles, as the extraction's subtrees report
  // them, so the first chunk can leave early; a stop is heard at each report.
  const RetainedCutParts parts{cut.mesh_, cut.parts_, cut.part_first_triangle_};
  Walker walker(c, parts, &m, observer, 4096);
  walker.Report();  // stopped before it began
  for (int i : roots) {
    if (!walker.stop().ok()) return walker.stop();
    walker.Subtree(cut.top_, 0, cut.root_begin_[i], cut.root_end_[i]);
  }
  if (walker.stop().ok()) walker.Report();
  if (!walker.stop().ok()) return walker.stop();
  if (walker.written() != cut.mesh_.triangle_count())
    return absl::InternalError("retained cut drew " + std::to_string(walker.written()) + " of " +
                               std::to_string(cut.mesh_.triangle_count()) + " triangles");

  ExtractStats& st = result.stats;
  st.eps_used = cut.eps_;
  st.triangles = int64_t(m.triangle_count());
  st.vertices = int64_t(m.vertex_count());
  for (uint8_t s : m.surface) ++st.triangles_per_surface[s];
  st.tets_visited = walker.walked();
  st.leaves = cut.leaves_;
  st.reordered = true;
  st.total_ms = st.extract_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_start).count();
  return result;
}

}  // namespace isostream
