// What an extraction keeps of its tree so that another view can be served by re-ordering the
// same triangles (retained_cut.h): the refined nodes and the leaves that emitted triangles, in
// preorder, as the traversal met them. Private to server/extract.
//
// A refined node's record is followed by its first-drawn child's subtree, then the other's
// (from `second`); the next view draws them in the order its own plane test gives, which is
// the test the traversal makes (ChildZeroFirst), so the order is the one a fresh extraction
// for that view would produce. A leaf names its triangles; a leaf crossed by several surfaces
// keeps what §4.3 orders its components by.
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>
#include <vector>

#include "server/extract/append_buffer.h"
#include "server/extract/tree_node.h"

namespace isostream::extract_internal {

struct CutRecord {
  enum Kind : uint8_t { kRefine, kLeaf, kMultiLeaf };
  // kRefine: the refinement vertex. kLeaf: the first triangle. kMultiLeaf: index into
  // CutPart::multi.
  uint64_t a;
  // kRefine: the record where the second-drawn child's subtree starts (the first's starts
  // right after this record). kLeaf: the triangle count.
  uint32_t b;
  Kind kind;
  TetClass cls;             // kRefine
  bool child0_drawn_first;  // kRefine: in the recorded order
};
static_assert(sizeof(CutRecord) == 16);

// A leaf crossed by several surfaces: its components [first, first + count) of
// CutPart::components, by ascending sorted-isovalue index, and what orders them for a view.
struct MultiLeaf {
  glm::dvec3 g;  // the leaf's gradient (§5), grid units
  PackedPoint v0;
  float f0;
  uint32_t first;
  uint32_t count;
};
struct CutComponent {
  uint32_t first_triangle;
  uint32_t triangles;
  uint32_t iso;  // sorted isovalue index (Context::iso)
};

// The records of one subtree (or of a whole frame, once joined). Triangle numbers are the
// subtree's own until the join adds the subtree's first frame triangle.
struct CutPart {
  AppendBuffer<CutRecord> records;
  std::vector<MultiLeaf> multi;
  std::vector<CutComponent> components;

  void clear() {
    records.clear();
    multi.clear();
    components.clear();
  }

  // Returns the record's index, for SecondChildStarts.
  uint32_t AddRefine(PackedPoint x, TetClass cls, bool child0_drawn_first) {
    const uint32_t i = uint32_t(records.size());
    *records.Extend(1) = {x, 0, CutRecord::kRefine, cls, child0_drawn_first};
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
  void AddLeaf(uint32_t first_triangle, uint32_t triangles) {
    if (triangles == 0) return;
    *records.Extend(1) = {first_triangle, triangles, CutRecord::kLeaf, TetClass{}, false};
  }
  void AddMultiLeaf(const MultiLeaf& leaf) {
    *records.Extend(1) = {multi.size(), 0, CutRecord::kMultiLeaf, TetClass{}, false};
    multi.push_back(leaf);
  }

  // Appends a subtree's records as one subtree here, its triangles numbered from
  // `first_triangle`.
  void Append(const CutPart& part, uint32_t first_triangle) {
    const uint32_t base = uint32_t(records.size());
    const uint64_t multi_base = multi.size();
    const uint32_t component_base = uint32_t(components.size());
    CutRecord* out = records.Extend(part.records.size());
    for (size_t i = 0; i < part.records.size(); ++i) {
      CutRecord r = part.records[i];
      if (r.kind == CutRecord::kRefine) r.b += base;
      else if (r.kind == CutRecord::kLeaf) r.a += first_triangle;
      else r.a += multi_base;
      out[i] = r;
    }
    for (MultiLeaf m : part.multi) {
      m.first += component_base;
      multi.push_back(m);
    }
    for (CutComponent c : part.components) {
      c.first_triangle += first_triangle;
      components.push_back(c);
    }
  }
};

}  // namespace isostream::extract_internal
