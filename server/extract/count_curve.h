// The triangle count as a function of eps, gathered by one count pass: what the budget search
// reads instead of counting again at every eps it tries. Private to server/extract.
//
// Etas are stored as 16-bit codes (extractor.h: code k stands for E_k = EtaCodeEps(k)), and a
// node stops where eta < eps: the count is a step function of eps that changes only at codes
// and is constant on each (E_{k-1}, E_k]. count(E_k) is therefore the count for every eps in
// that interval.
//
// A pass at eps = E_p visits every node that any eps >= E_p visits (saturated etas nest the
// meshes). A visited node T, reached below ancestors whose smallest code is `cap`, is a leaf for
// the codes k with code(T) < k <= cap (any k <= cap when T is at the finest level), and then
// adds its marching-tetrahedra triangles: so count(E_k) for all k >= p is a sum of intervals,
// kept as a difference array over [p, top]. Below p, the pass also shows how far the count
// stays the same: down to the largest code among the nodes that stopped above the finest level.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "server/extract/block_sets.h"
#include "server/extract/data_box_clip.h"
#include "server/extract/tree_node.h"

namespace isostream::extract_internal {

// The stored code of the eta at a node's refinement vertex (unused at the finest level).
inline uint32_t EtaCode(const Context& c, const Node& t) {
  return *reinterpret_cast<const uint16_t*>(c.store + t.xref_eta);
}

// Triangles of T as a leaf: marching tetrahedra for every isovalue crossing its corners
// (LeafEmitter's count: clipped where T straddles the data box).
inline int LeafTriangles(const Context& c, const Node& t) {
  const float fmin = std::min(std::min(t.f[0], t.f[1]), std::min(t.f[2], t.f[3]));
  const float fmax = std::max(std::max(t.f[0], t.f[1]), std::max(t.f[2], t.f[3]));
  int first, last;
  IsoRange(c, fmin, fmax, &first, &last);
  const bool straddles = c.clip && !InsideDataBox(c, t);
  int n = 0;
  for (int s = first; s < last; ++s) {
    const unsigned above = AboveCorners(t.f, c.iso[s]);
    const MarchingTetsCase& mc = (*c.cases)[above];
    if (mc.edge_count == 0) continue;
    if (straddles)
      n += StraddlingComponentTriangles(c, t, s, mc);
    else if (CornersAtIso(t.f, c.iso[s]) != 0)  // as LeafEmitter counts: no positions needed
      n += ComponentCrossings(c, t, s, mc).Triangles();
    else
      n += mc.edge_count - 2;
  }
  return n;
}

class CountCurve {
 public:
  // Counts at the codes k in [first, last].
  CountCurve(uint32_t first, uint32_t last)
      : first_(first), last_(last), diff_(size_t(last - first) + 2, 0) {}

  uint32_t first() const { return first_; }
  uint32_t last() const { return last_; }

  // n triangles at every code k in [lo, hi] (clipped to the curve's range).
  void Add(uint32_t lo, uint32_t hi, int64_t n) {
    lo = std::max(lo, first_);
    hi = std::min(hi, last_);
    if (n == 0 || lo > hi) return;
    diff_[lo - first_] += n;
    diff_[hi - first_ + 1] -= n;
  }

  // A node that stopped (a leaf, or culled) above the finest level with eta code `code` <
  // first: below the largest such code the count first changes, so it is constant on
  // [largest + 1, first].
  void NoteStop(uint32_t code) {
    if (code < first_) largest_stop_ = std::max(largest_stop_, int64_t(code));
  }
  // The largest code noted, or -1: then no node stopped above the finest level, and the count
  // is the same for every eps from 0 up to E_first.
  int64_t largest_stop() const { return largest_stop_; }

  void Merge(const CountCurve& other) {
    for (size_t i = 0; i < diff_.size(); ++i) diff_[i] += other.diff_[i];
    largest_stop_ = std::max(largest_stop_, other.largest_stop_);
  }

  // counts[i] = count(E_{first + i}).
  std::vector<int64_t> Counts() const {
    std::vector<int64_t> counts(size_t(last_ - first_) + 1);
    int64_t running = 0;
    for (size_t i = 0; i < counts.size(); ++i) counts[i] = running += diff_[i];
    return counts;
  }

 private:
  uint32_t first_, last_;
  std::vector<int64_t> diff_;
  int64_t largest_stop_ = -1;
};

}  // namespace isostream::extract_internal
