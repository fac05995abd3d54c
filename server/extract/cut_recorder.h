// What an extraction keeps of its tree so that another view can be served by re-ordering the
// same triangles (retained_cut.h): the refined nodes and the leaves that emitted triangles, in
// preorder, as the traversal met them, each leaf followed by its triangles. Private to
// server/extract.
//
// A refined node's record is followed by its first-drawn child's subtree, then the other's
// (from `b`); the next view draws them in the order its own plane test gives, which is the
// test the traversal makes (ChildZeroFirst), so the order is the one a fresh extraction for
// that view would produce. A leaf crossed by several surfaces keeps what §4.3 orders its
// components by. Triangles sit right after their leaf, in the same 16-byte slots, so that a
// walk in another order reads one stream, not records here and triangles elsewhere (which
// took half of its time).
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>
#include <vector>

#include "server/extract/append_buffer.h"
#include "server/extract/tree_node.h"

namespace isostream::extract_internal {

struct CutRecord {
  enum Kind : uint8_t { kRefine, kLeaf, kMultiLeaf, kComponent, kTriangle };
  // kRefine: the refinement vertex. kMultiLeaf: index into CutPart::multi. kTriangle: its first
  // two vertices (low, high half).
  uint64_t a;
  // kRefine: the record where the second-drawn child's subtree starts (the first's starts
  // right after this record). kLeaf, kComponent: how many triangles follow. kMultiLeaf: how
  // many components follow. kTriangle: its third vertex.
  uint32_t b;
  Kind kind;
  // kRefine: the class. kComponent: the sorted isovalue index (Context::iso). kTriangle: the
  // surface (the request's isovalue index).
  uint8_t c;
  bool child0_drawn_first;  // kRefine: in the recorded order
  uint8_t unused = 0;
};
static_assert(sizeof(CutRecord) == 16);

// A leaf crossed by several surfaces: what orders its components for a view.
struct MultiLeaf {
  glm::dvec3 g;  // the leaf's gradient (§5), grid units
  PackedPoint v0;
  float f0;
};

// The records of one subtree (or of a whole frame, once joined). Vertex numbers are the
// subtree's own until the join maps them to the frame's.
struct CutPart {
  AppendBuffer<CutRecord> records;
  std::vector<MultiLeaf> multi;

  void clear() {
    records.clear();
    multi.clear();
  }

  // Returns the record's index, for SecondChildStarts.
  uint32_t AddRefine(PackedPoint x, TetClass cls, bool child0_drawn_first) {
    const uint32_t i = uint32_t(records.size());
    *records.Extend(1) = {x, 0, CutRecord::kRefine, cls.value, child0_drawn_first};
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
  // A leaf with one surface: its `count` triangles (3 vertices and a surface each).
  void AddLeaf(const uint32_t* vertices, const uint8_t* surfaces, uint32_t count) {
    if (count == 0) return;
    *records.Extend(1) = {0, count, CutRecord::kLeaf, 0, false};
    AddTriangles(vertices, surfaces, count);
  }
  // A leaf with several surfaces: `components` blocks follow (AddComponent).
  void AddMultiLeaf(const MultiLeaf& leaf, uint32_t components) {
    *records.Extend(1) = {multi.size(), components, CutRecord::kMultiLeaf, 0, false};
    multi.push_back(leaf);
  }
  void AddComponent(uint8_t iso, const uint32_t* vertices, const uint8_t* surfaces,
                    uint32_t count) {
    *records.Extend(1) = {0, count, CutRecord::kComponent, iso, false};
    AddTriangles(vertices, surfaces, count);
  }

  // Appends a subtree's records as one subtree here, its vertices renumbered by `to_frame`.
  void Append(const CutPart& part, const uint32_t* to_frame) {
    const uint32_t base = uint32_t(records.size());
    const uint64_t multi_base = multi.size();
    CutRecord* out = records.Extend(part.records.size());
    for (size_t i = 0; i < part.records.size(); ++i) {
      CutRecord r = part.records[i];
      if (r.kind == CutRecord::kTriangle) {
        r.a = uint64_t(to_frame[uint32_t(r.a)]) | uint64_t(to_frame[r.a >> 32]) << 32;
        r.b = to_frame[r.b];
      } else if (r.kind == CutRecord::kRefine) {
        r.b += base;
      } else if (r.kind == CutRecord::kMultiLeaf) {
        r.a += multi_base;
      }
      out[i] = r;
    }
    multi.insert(multi.end(), part.multi.begin(), part.multi.end());
  }

 private:
  void AddTriangles(const uint32_t* v, const uint8_t* surfaces, uint32_t count) {
    CutRecord* out = records.Extend(count);
    for (uint32_t t = 0; t < count; ++t)
      out[t] = {uint64_t(v[3 * t]) | uint64_t(v[3 * t + 1]) << 32, v[3 * t + 2],
                CutRecord::kTriangle, surfaces[t], false};
  }
};

}  // namespace isostream::extract_internal
