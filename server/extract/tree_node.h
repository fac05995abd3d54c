// A tetrahedron of the bisection tree as the extractor carries it, the request context it is
// read against, and the per-node steps of Gerstner's traversal (§3-§5): decide (cull, leaf or
// refine) and bisect (children in draw order, their values and §5 gradients). Private to
// server/extract.
#pragma once

#include <algorithm>
#include <cstdint>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include "server/extract/extract_request.h"
#include "server/extract/marching_tets.h"
#include "server/hierarchy/bisection.h"
#include "server/hierarchy/block_tables.h"
#include "server/hierarchy/hierarchy.h"

namespace isostream::extract_internal {

// A grid point packed as x | y << 21 | z << 42. Coordinates are below 2^13 (k <= 12), so sums
// of two points stay inside their fields: a refinement vertex is (v0 + v3) >> 1 (both ends have
// the same parity per axis, so no bit crosses a field), and a + b is an edge's doubled midpoint.
using PackedPoint = uint64_t;
inline constexpr int kFieldBits = 21;
inline constexpr uint64_t kFieldMask = (uint64_t{1} << kFieldBits) - 1;
inline PackedPoint Pack(const glm::ivec3& p) {
  return uint64_t(p.x) | (uint64_t(p.y) << kFieldBits) | (uint64_t(p.z) << (2 * kFieldBits));
}
inline glm::ivec3 Unpack(PackedPoint p) {
  return {int(p & kFieldMask), int((p >> kFieldBits) & kFieldMask), int(p >> (2 * kFieldBits))};
}

struct Node {
  PackedPoint v[4];  // canonical vertex order of the class
  float f[4];
  glm::dvec3 g;  // gradient of the linear interpolant on T, grid units
  // Byte offsets in the store of the refinement vertex's sample and eta (unused at the finest
  // level).
  uint64_t xref_value, xref_eta;
  TetClass cls;
  // Which child Bisect draws first, decided when the node is made: off the chain from a node
  // to its far child, where the plane test would delay every step (unused at the finest level).
  bool child0_first;
  uint8_t level;  // at most 3 * 16
  // Count passes that gather a CountCurve only: the smallest eta code of the node's ancestors.
  uint32_t eta_cap;
};

// Everything the traversal reads, fixed for one request.
struct Context {
  const char* store = nullptr;                                   // Hierarchy::bricks()
  const uint64_t* value_bytes[3] = {nullptr, nullptr, nullptr};  // Hierarchy::value_byte_offsets()
  const uint64_t* eta_bytes[3] = {nullptr, nullptr, nullptr};    // Hierarchy::eta_byte_offsets()
  int k = 0, n = 0;
  glm::ivec3 data_max{0};             // data box is [0, data_max]
  bool clip = false;                  // the data box is smaller than the cube
  float iso[kMaxSurfaces];            // ascending
  uint8_t iso_surface[kMaxSurfaces];  // request index of iso[i]
  int iso_count = 0;
  float eps = 0;
  bool ordered = true;
  bool orthographic = false;
  glm::dvec3 eye{0.0}, dir{0.0};  // grid space
  NormalMode normals = NormalMode::kSmooth;
  GridToWorld xf;
  glm::vec3 world_origin{0.0f}, world_spacing{1.0f};  // xf in single precision
  glm::vec3 inv_spacing{1.0f};                        // grid-space gradient -> world-space gradient
  // A bound on the parameter t (or 1 - t) of any crossing with a stored coordinate that rounds
  // onto an end's (extractor.cpp, SnapTau): only components with a corner within snap_tau times
  // their value range of the isovalue need their crossings placed exactly (CornersNearIso,
  // ComponentCrossings, OffTheEnds).
  float snap_tau = 0;
  const ReferenceTets* tables = nullptr;
  const BlockTables* blocks = nullptr;
  int block_level = 0;  // 3k - 3: nodes refined here run the last three levels as one block
                        // (-1: none)
  const MarchingTets* cases = nullptr;
  uint8_t negative[kNumTetClasses];  // ReferenceTet::left_handed, beside the other per-class data
  // Per class, against ReferenceTet::plane_normal_int (entries 0 or +-1). Perspective: the
  // eye is not on child 1's side of the plane through grid point x iff normal . x >=
  // plane_at_least (normal . eye rounded up, clamped far outside any grid: MakeContext), and
  // normal . x is the sum of x's fields where the normal is +1 minus the sum where it is -1,
  // each taken from a packed point by one multiply (FieldSum). Orthographic: whether child 0
  // is drawn first (the same for every node).
  uint64_t plane_plus[kNumTetClasses], plane_minus[kNumTetClasses];
  int64_t plane_at_least[kNumTetClasses];
  uint8_t ortho_child0_first[kNumTetClasses];
  // 1 / (real length of one normalised class unit) per level: half the level's cube cell.
  double inv_unit[3 * 16 + 1];

  static uint64_t Sum(const uint64_t* const table[3], PackedPoint p) {
    return table[0][p & kFieldMask] + table[1][(p >> kFieldBits) & kFieldMask] +
           table[2][p >> (2 * kFieldBits)];
  }
  uint64_t ValueOffset(PackedPoint p) const { return Sum(value_bytes, p); }
  uint64_t EtaOffset(PackedPoint p) const { return Sum(eta_bytes, p); }
  uint64_t ValueOffset(const glm::ivec3& p) const {
    return value_bytes[0][p.x] + value_bytes[1][p.y] + value_bytes[2][p.z];
  }
  float F(uint64_t value_offset) const {
    return *reinterpret_cast<const float*>(store + value_offset);
  }
  float Eta(uint64_t eta_offset) const {
    return DecodeEta(*reinterpret_cast<const uint16_t*>(store + eta_offset));
  }
  float F(const glm::ivec3& p) const { return F(ValueOffset(p)); }
};

enum class Decision { kCull, kLeaf, kRefine };

// Lowest sorted-iso index with iso > lo, and one past the highest with iso <= hi.
inline void IsoRange(const Context& c, float lo, float hi, int* first, int* last) {
  int a = 0;
  while (a < c.iso_count && c.iso[a] <= lo) ++a;
  int b = a;
  while (b < c.iso_count && c.iso[b] <= hi) ++b;
  *first = a;
  *last = b;
}

// For a leaf, [*first, *last) are the sorted isovalues that cross it.
// Always inlined, as Bisect: GCC's choice flipped with unrelated changes elsewhere (a call
// here cost ~2.5%).
__attribute__((always_inline)) inline Decision Decide(const Context& c, const Node& t, int* first,
                                                      int* last) {
  if (c.clip) {
    const glm::ivec3 v[4] = {Unpack(t.v[0]), Unpack(t.v[1]), Unpack(t.v[2]), Unpack(t.v[3])};
    for (int a = 0; a < 3; ++a) {
      const int lo = std::min(std::min(v[0][a], v[1][a]), std::min(v[2][a], v[3][a]));
      if (lo >= c.data_max[a]) return Decision::kCull;
    }
  }
  const float fmin = std::min(std::min(t.f[0], t.f[1]), std::min(t.f[2], t.f[3]));
  const float fmax = std::max(std::max(t.f[0], t.f[1]), std::max(t.f[2], t.f[3]));
  if (t.level == 3 * c.k) {
    IsoRange(c, fmin, fmax, first, last);  // exact: a crossing needs fmin < iso <= fmax
    return *first < *last ? Decision::kLeaf : Decision::kCull;
  }
  const float e = c.Eta(t.xref_eta);
  // Any iso in [fmin - e, fmax + e] may meet f_full inside T.
  int a = 0;
  while (a < c.iso_count && c.iso[a] < fmin - e) ++a;
  if (a == c.iso_count || c.iso[a] > fmax + e) return Decision::kCull;
  if (e >= c.eps) return Decision::kRefine;
  IsoRange(c, fmin, fmax, first, last);
  return *first < *last ? Decision::kLeaf : Decision::kCull;
}

inline Decision Decide(const Context& c, const Node& t) {
  int first, last;
  return Decide(c, t, &first, &last);
}

// The multiplier whose product with a packed point holds, in bits 42-57, the sum of the
// point's fields on the axes in `axes` (bit a: axis a). Field a times 2^(42 - 21a) lands there;
// the cross terms land below bit 36 (no carry reaches bit 42: coordinates are below 2^13) or
// at bit 63 and above.
inline uint64_t FieldSumMultiplier(unsigned axes) {
  uint64_t m = 0;
  for (int a = 0; a < 3; ++a)
    if ((axes >> a) & 1) m += uint64_t{1} << (2 * kFieldBits - a * kFieldBits);
  return m;
}
inline int64_t FieldSum(PackedPoint p, uint64_t multiplier) {
  return int64_t(((p * multiplier) >> (2 * kFieldBits)) & 0xffff);
}

// normal . x for the integer normal of class cls's separating plane: what the perspective
// plane test compares with the eye's side. It depends on the point and the class, not on the
// view, so a retained cut keeps it instead of the point.
inline int64_t PlaneSide(const Context& c, TetClass cls, PackedPoint x) {
  return FieldSum(x, c.plane_plus[cls.value]) - FieldSum(x, c.plane_minus[cls.value]);
}

// Whether child 0 of a tetrahedron of class cls with refinement vertex x is drawn first:
// unless the eye is on its side of the separating plane.
inline bool ChildZeroFirst(const Context& c, TetClass cls, PackedPoint x) {
  if (!c.ordered) return true;
  if (c.orthographic) return c.ortho_child0_first[cls.value];
  return PlaneSide(c, cls, x) >= c.plane_at_least[cls.value];
}
// The same test given the plane side.
inline bool ChildZeroFirstAtSide(const Context& c, TetClass cls, int64_t side) {
  if (!c.ordered) return true;
  if (c.orthographic) return c.ortho_child0_first[cls.value];
  return side >= c.plane_at_least[cls.value];
}

// §5: the wavelet at the refinement vertex of a tetrahedron at `level` (value fx there, f0 and
// f3 at the refinement edge's ends), per class unit; child ch's gradient is the parent's plus
// it times ReferenceTet::gradient_update[ch]. One formula for Bisect and for the blocks'
// lazily derived gradients, so they agree bit for bit.
inline double Wavelet(const Context& c, float fx, float f0, float f3, int level) {
  return (double(fx) - 0.5 * (double(f0) + double(f3))) * c.inv_unit[level];
}

// Whether an emitting traversal reads the nodes' §5 gradients: for flat normals, and to order
// several surfaces crossing one leaf (smooth normals come from central differences, and where
// those vanish, from the edge: LeafEmitter::VanishedGradient). A recording one keeps them for
// several surfaces in any order: the cut may be re-ordered for another view (retained_cut.h).
inline bool NeedsGradients(const Context& c, bool recording) {
  return c.normals != NormalMode::kSmooth || (c.iso_count > 1 && (c.ordered || recording));
}

// The draw order of a leaf's `count` components, far to near (§4.3), into order[] as indices
// 0..count-1 of their isovalues iso(0) < ... < iso(count - 1). gradient() is the leaf's (§5),
// read only when the order needs it; f0 and v0 are one corner's value and point. One function
// for the traversal and for re-ordering a retained cut, so both decide alike.
template <typename Gradient, typename Iso>
inline void ComponentOrder(const Context& c, Gradient gradient, float f0, PackedPoint v0, Iso iso,
                           int count, int* order) {
  int n = 0;
  if (!c.ordered) {
    for (int i = 0; i < count; ++i) order[n++] = i;
  } else if (c.orthographic) {
    const bool descending = glm::dot(gradient(), c.dir) > 0;  // f grows away from the eye
    for (int i = 0; i < count; ++i) order[n++] = descending ? count - 1 - i : i;
  } else {
    // Isovalues above f_T(eye), highest first; then those at or below it, lowest first.
    const double fe = f0 + glm::dot(gradient(), c.eye - glm::dvec3(Unpack(v0)));
    int split = 0;
    while (split < count && iso(split) <= fe) ++split;
    for (int i = count - 1; i >= split; --i) order[n++] = i;
    for (int i = 0; i < split; ++i) order[n++] = i;
  }
}

// The children of t in draw order: the farther one (drawn first) in *first. Without
// kGradient (counting) the children's §5 gradients are left unset: only emission reads them.
// Always inlined: the traversal loop is its only hot caller, and a call here cost ~1%.
template <bool kGradient = true>
__attribute__((always_inline)) inline void Bisect(const Context& c, const Node& t, Node* first,
                                                  Node* second) {
  const ReferenceTet& rt = (*c.tables)[t.cls];
  const PackedPoint x = (t.v[0] + t.v[3]) >> 1;
  const float fx = c.F(t.xref_value);
  const float fp[5] = {t.f[0], t.f[1], t.f[2], t.f[3], fx};
  const PackedPoint points[5] = {t.v[0], t.v[1], t.v[2], t.v[3], x};
  const double w = kGradient ? Wavelet(c, fx, t.f[0], t.f[3], t.level) : 0.0;
  const bool child0_first = t.child0_first;
  for (int ch = 0; ch < 2; ++ch) {
    Node& o = *((ch == 0) == child0_first ? first : second);
    const uint8_t* cp = rt.child_point[ch].data();
    for (int i = 0; i < 4; ++i) {
      o.v[i] = points[cp[i]];
      o.f[i] = fp[cp[i]];
    }
    if constexpr (kGradient) o.g = t.g + w * rt.gradient_update[ch];
    o.cls = rt.child[ch];
    o.level = uint8_t(t.level + 1);
    // The child's first read is its refinement vertex: start fetching it now (the second
    // child has a whole subtree's time to arrive).
    if (o.level < 3 * c.k) {
      const PackedPoint ox = (o.v[0] + o.v[3]) >> 1;
      o.xref_value = c.ValueOffset(ox);
      o.xref_eta = c.EtaOffset(ox);
      __builtin_prefetch(c.store + o.xref_value);
      __builtin_prefetch(c.store + o.xref_eta);
      o.child0_first = ChildZeroFirst(c, o.cls, ox);
    }
  }
}

// Every vertex of t inside the data box (clipping is needed otherwise).
inline bool InsideDataBox(const Context& c, const Node& t) {
  for (int i = 0; i < 4; ++i)
    for (int a = 0; a < 3; ++a)
      if (Unpack(t.v[i])[a] > c.data_max[a]) return false;
  return true;
}

}  // namespace isostream::extract_internal
