// What an extraction keeps of its tree so that another view can be served by re-ordering the
// same triangles (retained_cut.h): the refined nodes and the leaves that emitted triangles, in
// preorder, as the traversal met them. Private to server/extract.
//
// A refined node's record is followed by its first-drawn child's subtree, then the other's
// (from `b`); the next view draws them in the order its own plane test gives, which is the
// test the traversal makes (ChildZeroFirst), so the order is the one a fresh extraction for
// that view would produce. A leaf names its triangles; a leaf crossed by several surfaces
// keeps what §4.3 orders its components by. Each subtree of the parallel split records into
// its own CutPart, numbering triangles from its own first, so nothing is copied at the join.
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>
#include <utility>
#include <vector>

#include "server/extract/append_buffer.h"
#include "server/extract/tree_node.h"

namespace isostream::extract_internal {

struct CutRecord {
  enum Kind : uint8_t { kRefine, kLeaf, kMultiLeaf, kComponent, kPart };
  // kRefine: the plane side of the refinement vertex (PlaneSide, as int64_t). kLeaf,
  // kComponent: the first triangle (of the part).
  // kMultiLeaf: index into CutPart::multi. kPart: the part (a subtree of the split).
  uint64_t a;
  // kRefine: the record where the second-drawn child's subtree starts (the first's starts
  // right after this record). kLeaf, kComponent: the triangle count. kMultiLeaf: how many
  // kComponent records follow.
  uint32_t b;
  Kind kind;
  // kRefine: the class. kComponent: the sorted isovalue index (Context::iso).
  uint8_t c;
  bool child0_drawn_first;  // kRefine: in the recorded order
};
static_assert(sizeof(CutRecord) == 16);

// A leaf crossed by several surfaces: what orders its components for a view.
struct MultiLeaf {
  glm::dvec3 g;  // the leaf's gradient (§5), grid units
  PackedPoint v0;
  float f0;
};

// The records of one subtree of the split (or of the tree above them).
struct CutPart {
  AppendBuffer<CutRecord> records;
  std::vector<MultiLeaf> multi;

  void clear() {
    records.clear();
    multi.clear();
  }
  size_t capacity_bytes() const {
    return records.capacity() * sizeof(CutRecord) + multi.capacity() * sizeof(MultiLeaf);
  }

  // Returns the record's index, for SecondChildStarts.
  uint32_t AddRefine(int64_t plane_side, TetClass cls, bool child0_drawn_first) {
    const uint32_t i = uint32_t(records.size());
    *records.Extend(1) = {uint64_t(plane_side), 0, CutRecord::kRefine, cls.value,
                          child0_drawn_first};
    return i;
  }
  // The second-drawn child of refine record i starts here. A node whose first child left no
  // record is dropped (it is the last record): its second child then stands in its place,
  // and nothing has pointed past it yet.
  void SecondChildStarts(uint32_t i) {
    if (records.size() == size_t(i) + 1) {
      records.Shrink(i);
      return;
    }
    records[i].b = uint32_t(records.size());
  }
  // A leaf with one surface: triangles [first, first + count).
  void AddLeaf(uint32_t first, uint32_t count) {
    if (count > 0) *records.Extend(1) = {first, count, CutRecord::kLeaf, 0, false};
  }
  // A leaf with several surfaces: `components` AddComponent records follow.
  void AddMultiLeaf(const MultiLeaf& leaf, uint32_t components) {
    *records.Extend(1) = {multi.size(), components, CutRecord::kMultiLeaf, 0, false};
    multi.push_back(leaf);
  }
  void AddComponent(uint8_t iso, uint32_t first, uint32_t count) {
    *records.Extend(1) = {first, count, CutRecord::kComponent, iso, false};
  }
  void AddPart(uint32_t part) { *records.Extend(1) = {part, 0, CutRecord::kPart, 0, false}; }
};

// The refinements the split into parallel subtrees makes above them (extractor.cpp), noted
// while it runs and recorded once the frame is whole, in its draw order, with a kPart record
// where each subtree goes (the subtrees record into parts of their own).
struct SplitTree {
  struct Entry {
    int64_t plane_side = 0;  // of the refinement vertex (PlaneSide), once refined
    TetClass cls;
    bool child0_first = false;
    int kids[2] = {-1, -1};  // in draw order, once refined
    int item = -1;           // the subtree it became
  };
  std::vector<Entry> entries;
  std::vector<std::pair<int, int>> roots;  // (initial tetrahedron, entry) in draw order

  // Records the tree into `top`; the records of initial tetrahedron i go to
  // [root_begin[i], root_end[i]).
  void Record(CutPart* top, uint32_t* root_begin, uint32_t* root_end) const {
    for (const auto& [initial, entry] : roots) {
      root_begin[initial] = uint32_t(top->records.size());
      Record(entry, top);
      root_end[initial] = uint32_t(top->records.size());
    }
  }

 private:
  void Record(int e, CutPart* top) const {
    const Entry& n = entries[size_t(e)];
    if (n.kids[0] >= 0) {
      const uint32_t record = top->AddRefine(n.plane_side, n.cls, n.child0_first);
      Record(n.kids[0], top);
      top->SecondChildStarts(record);
      Record(n.kids[1], top);
    } else if (n.item >= 0) {
      top->AddPart(uint32_t(n.item));
    }
  }
};

}  // namespace isostream::extract_internal
