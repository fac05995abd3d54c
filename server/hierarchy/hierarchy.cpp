// Saturated error bounds for the tetrahedral bisection hierarchy (Gerstner §3; the additive
// saturation of Gerstner, Rumpf & Weikard, "Error indicators for multilevel visualization").
//
// Why the bound holds. Let T be a hierarchy tetrahedron with refinement edge (a, b) and
// refinement vertex x, and T1, T2 its children with refinement vertices y1, y2. On T_i the
// linear interpolant L_{T_i} f differs from L_T f by w(x) * phi, where
// w(x) = f(x) - (f(a) + f(b)) / 2 is the wavelet coefficient and phi in [0, 1] is the hat of x
// on T_i. By induction over the levels (a finest tetrahedron has error 0),
//   max_T |f_full - L_T f| <= |w(x)| + max_i max_{T_i} |f_full - L_{T_i} f|
//                          <= |w(x)| + max(eta(y1), eta(y2)).
// y1 and y2 are children of x in the diamond sense (their diamonds contain T1, T2, whose parent
// lies in x's diamond), so defining
//   eta(x) = |w(x)| + max over all diamond children y of eta(y)
// makes eta(x) an upper bound on every tetrahedron of x's diamond, and eta(child) <= eta(x),
// which is the saturation that keeps "refine iff eta >= eps" free of hanging nodes: a refined
// diamond's parents have eta at least as large and are refined too. The wavelet coefficient is
// the same for every tetrahedron of a diamond because they share the refinement edge.
//
// Children of a diamond centred at x with u = 2^h (derived in refinement_vertex.h's terms and
// checked against the bisection tree in tests/unit/hierarchy_test.cpp):
//   cube centre : the 6 face centres x +- u e_a            (same h)
//   face centre : the 4 edge centres x +- u e_a, a odd      (same h)
//   edge centre : the 8 cube centres x + (+-u/2)^3           (h - 1), those inside the domain
// Bottom-up order is therefore: for h = 0..k-1, edges, then faces, then cubes.
//
// How it is computed (the values are exactly those of the definition: eta in float, each
// level rounded up from |w| + max child in double, and only the stored copy rounded up once
// more to bfloat16; tests/unit/hierarchy_test.cpp checks every stored bit against a plain
// recursion over the tree). One parallel pass per scale h, over tiles of 8^3 cells of the
// scale's lattice (spacing 2^h): a scale's diamonds reach one lattice point each way, so a
// tile's eta follows from its 9^3 lattice samples (and, for edge centres, the previous
// scale's cube centres half a cell away), all in L1. The builder touches no memory beyond
// the bricks it returns:
//  * Scale 0 (7/8 of the points): a tile is a brick. The pass writes each brick whole
//    (samples and eta, first touch of its pages).
//  * Scales 1..k-1 gather their samples from the linear array and store each point's bfloat16
//    eta into its brick. The float eta of each scale's cube centres, which the next scale's
//    edge centres need, overwrites their samples in the linear array: nothing reads those
//    samples again (a diamond reads the samples at its refinement edge's ends, coarser
//    points, and the brick store already holds all samples).
// That is the whole cube's builder. Where stand-ins hold the planes deep in the padding
// (stored_planes.h), the stored planes are no regular lattice: stand_in_build.cpp evaluates the
// same definition point by point through the stand-in maps, in the same arithmetic.
#include "server/hierarchy/hierarchy.h"

#include <sys/mman.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <limits>
#include <new>
#include <string>

#include "server/hierarchy/eta_rounding.h"
#include "server/hierarchy/refinement_vertex.h"
#include "server/hierarchy/stand_in_build.h"
#include "shared/arena_size.h"

namespace isostream {
namespace {

using hierarchy_internal::DiamondEta;
using hierarchy_internal::IsFinite;

// The bricks are first touched by the parallel scale-0 pass; asking for transparent huge
// pages cuts the page faults of a 513^3 build from ~330 k to ~650. Only a hint: ignored where
// THP is off. (First-touching fresh memory is still most of a cold 513^3 build on the
// project's VM: BENCHMARKS.md.)
void AdviseHugePages(void* data, size_t bytes) {
  constexpr uintptr_t kHuge = uintptr_t{2} << 20;
  const uintptr_t begin = (reinterpret_cast<uintptr_t>(data) + kHuge - 1) & ~(kHuge - 1);
  const uintptr_t end = (reinterpret_cast<uintptr_t>(data) + bytes) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
}

// eta of the diamond at tile point p with refinement edge (p - d, p + d), given the largest
// eta of its children (0 if it has none).
inline float Eta(const float* t, int p, int d, float worst) {
  return DiamondEta(t[p], t[p + d], t[p - d], worst);
}

}  // namespace

class HierarchyBuilder {
 public:
  // `samples`: the linear (x fastest) cube, consumed (cube centres' float eta overwrite their
  // samples, see the top). `h`: laid out (SetUpStore), bricks not yet written.
  HierarchyBuilder(int k, float* samples, Hierarchy* h)
      : s_(samples),
        bricks_(h->bricks_.data()),
        offset_{h->axis_offset_[0].data(), h->axis_offset_[1].data(), h->axis_offset_[2].data()},
        k_(k),
        n_((1 << k) + 1),
        last_(1 << k) {}

  // False if a sample is not finite (then eta is meaningless and the build is abandoned).
  bool Run(const HierarchyBuildOptions& options) {
    stop_ = options.stop;
    const size_t total = size_t(n_) * n_ * n_;
    const bool report = options.progress && total > (size_t{1} << 24);
    size_t left = total;  // points of scale >= h (and the 8 corners)
    for (int h = 0; h < k_ && !Stopped(); ++h) {
      if (h == 0) {
        if (!ForEachTile(0, [&](int tx, int ty, int tz) { return FinestTile(tx, ty, tz); }))
          return false;
      } else {
        ForEachTile(h, [&](int tx, int ty, int tz) { return CoarseTile(h, tx, ty, tz); });
      }
      const size_t side = size_t(last_ >> (h + 1)) + 1;
      left = side * side * side;
      if (report) options.progress(std::min(0.99, static_cast<double>(total - left) / total));
    }
    if (report) options.progress(1.0);
    return true;
  }

 private:
  static constexpr int kT = 9;                   // tile side in lattice points
  static constexpr int kTY = kT, kTZ = kT * kT;  // tile strides
  static constexpr int kQ = kT + 1;              // edge-children tile side
  static constexpr int kQY = kQ, kQZ = kQ * kQ;
  static_assert(HierarchyBrick::kMask + 1 == kT - 1, "scale-0 tiles are bricks");
  static constexpr int kAhead = 3 * (kT - 1);  // prefetch distance in lattice points

  bool Stopped() const { return stop_ && stop_->load(std::memory_order_relaxed); }

  // Scale h's lattice (spacing u = 2^h) cut into tiles of 8^3 cells, in parallel; tile rows
  // along x stay on one thread (consecutive in memory).
  template <typename F>
  bool ForEachTile(int h, F&& tile) {
    const int cells = last_ >> h;            // lattice cells per axis
    const int tiles = cells / (kT - 1) + 1;  // tiles per axis (each owns 8 points of it)
    std::atomic<bool> all_ok{true};
    auto rows = [&](const tbb::blocked_range<int>& r) {
      if (Stopped()) return;  // the remaining ranges are skipped, each at one load's cost
      bool ok = true;
      for (int zy = r.begin(); zy != r.end(); ++zy)
        for (int tx = 0; tx < tiles; ++tx) ok &= tile(tx, zy % tiles, zy / tiles);
      if (!ok) all_ok.store(false, std::memory_order_relaxed);
    };
    tbb::parallel_for(tbb::blocked_range<int>(0, tiles * tiles), rows);
    return all_ok.load();
  }

  // The diamonds of one scale inside a tile: the 9^3 lattice points t (samples; the last
  // plane on each axis is the next tile's first, clipped to the cube: c[] points per axis),
  // eta e of the points with an odd lattice coordinate. Cube sizes are odd and tiles start at
  // multiples of 8 lattice cells, so the c[] are odd: every odd coordinate has both lattice
  // neighbours in the tile, and a diamond's refinement-edge ends and its edge/face/cube
  // children are such neighbours. Tile coordinates are congruent to lattice ones mod 8, so
  // the edge directions (EvenEndSign) read the same. Edge centres' children (kEdgeChildren,
  // scales >= 1) are the previous scale's cube centres half a cell away on every axis: q
  // holds them at half-coordinates -1/2 .. 8 + 1/2, 0 outside the cube (eta >= 0, so that
  // is the same as leaving them out).
  template <bool kEdgeChildren>
  static void TileEta(const int c[3], const float* t, const float* q, float* e) {
    if (c[0] == kT && c[1] == kT && c[2] == kT) {
      TileEtaT<kEdgeChildren, true>(c, t, q, e);  // constant bounds: unrolled
    } else {
      TileEtaT<kEdgeChildren, false>(c, t, q, e);
    }
  }
  template <bool kEdgeChildren, bool kFull>
  static void TileEtaT(const int c[3], const float* t, const float* q, float* e) {
    auto sign = [](int v) { return ((v & 3) == 3) ? 1 : -1; };  // EvenEndSign, lattice units
    auto edge_children = [q](int x, int y, int z) {
      if (!kEdgeChildren) return 0.0f;
      const float* b = q + z * kQZ + y * kQY + x;  // children at b + {0,1} x {0,kQY} x {0,kQZ}
      return std::max(
          std::max(std::max(b[0], b[1]), std::max(b[kQY], b[kQY + 1])),
          std::max(std::max(b[kQZ], b[kQZ + 1]), std::max(b[kQZ + kQY], b[kQZ + kQY + 1])));
    };
    const int cx = kFull ? kT : c[0], cy = kFull ? kT : c[1], cz = kFull ? kT : c[2];
    // Edge centres: one odd coordinate.
    for (int z = 0; z < cz; z += 2)
      for (int y = 0; y < cy; y += 2) {
        for (int x = 1; x < cx; x += 2) {
          const int p = z * kTZ + y * kTY + x;
          e[p] = Eta(t, p, 1, edge_children(x, y, z));
        }
        if (y + 1 < cy)
          for (int x = 0; x < cx; x += 2) {
            const int p = z * kTZ + (y + 1) * kTY + x;
            e[p] = Eta(t, p, kTY, edge_children(x, y + 1, z));
          }
        if (z + 1 < cz)
          for (int x = 0; x < cx; x += 2) {
            const int p = (z + 1) * kTZ + y * kTY + x;
            e[p] = Eta(t, p, kTZ, edge_children(x, y, z + 1));
          }
      }
    // Face centres: two odd coordinates; children the 4 edge centres one point along them.
    for (int z = 0; z < cz; ++z)
      for (int y = 0; y < cy; ++y) {
        const int zo = z & 1, yo = y & 1;
        if (zo && yo) {  // x even
          const int d = sign(y) * kTY + sign(z) * kTZ;
          for (int x = 0; x < cx; x += 2) {
            const int p = z * kTZ + y * kTY + x;
            e[p] =
                Eta(t, p, d,
                    std::max(std::max(e[p - kTY], e[p + kTY]), std::max(e[p - kTZ], e[p + kTZ])));
          }
        } else if (zo || yo) {  // x odd, and one of y, z
          const int a = yo ? kTY : kTZ;
          const int da = yo ? sign(y) * kTY : sign(z) * kTZ;
          for (int x = 1; x < cx; x += 2) {
            const int p = z * kTZ + y * kTY + x;
            e[p] = Eta(t, p, sign(x) + da,
                       std::max(std::max(e[p - 1], e[p + 1]), std::max(e[p - a], e[p + a])));
          }
        }
      }
    // Cube centres: all odd (never on the shared last plane); children the 6 face centres.
    for (int z = 1; z < cz; z += 2)
      for (int y = 1; y < cy; y += 2)
        for (int x = 1; x < cx; x += 2) {
          const int p = z * kTZ + y * kTY + x;
          const float worst =
              std::max(std::max(std::max(e[p - 1], e[p + 1]), std::max(e[p - kTY], e[p + kTY])),
                       std::max(e[p - kTZ], e[p + kTZ]));
          e[p] = Eta(t, p, sign(x) + sign(y) * kTY + sign(z) * kTZ, worst);
        }
  }

  // Scale 0: a tile is a brick plus the next brick's first plane on each axis. Writes the
  // brick whole (samples, scale-0 eta, 0 for coarser points, whose eta comes later, and for
  // points beyond the cube, which are never read but keep the store deterministic) and
  // leaves the cube centres' float eta in the linear array for scale 1's edge centres.
  bool FinestTile(int bx, int by, int bz) {
    const int x0 = bx * (kT - 1), y0 = by * (kT - 1), z0 = bz * (kT - 1);
    const int c[3] = {std::min(kT, n_ - x0), std::min(kT, n_ - y0), std::min(kT, n_ - z0)};
    HierarchyBrick* brick = &bricks_[(size_t(bz) * brick_count() + by) * brick_count() + bx];
    float* s = s_ + (size_t(z0) * n_ + y0) * n_ + x0;
    if (c[0] == kT && c[1] == kT && c[2] == kT) return FinestTileT<true>(c, s, brick);
    return FinestTileT<false>(c, s, brick);
  }
  template <bool kFull>
  bool FinestTileT(const int c[3], float* s, HierarchyBrick* brick) {
    alignas(64) float t[kT * kT * kT];
    alignas(64) float e[kT * kT * kT];
    const size_t sy = size_t(n_), sz = size_t(n_) * n_;
    const int cx = kFull ? kT : c[0], cy = kFull ? kT : c[1], cz = kFull ? kT : c[2];
    // The tile's rows continue the previous tile's: too many streams for the hardware
    // prefetcher, so fetch ahead for the tile after next.
    const float* end = s_ + size_t(n_) * sz;
    for (int z = 0; z < cz; ++z)
      for (int y = 0; y < cy; ++y) {
        const float* row = s + z * sz + y * sy;
        std::memcpy(t + z * kTZ + y * kTY, row, sizeof(float) * cx);
        if (end - row > kAhead) __builtin_prefetch(row + kAhead);
      }
    TileEtaT<false, kFull>(c, t, nullptr, e);

    constexpr int kB = kT - 1;
    const int bxn = std::min(kB, cx), byn = std::min(kB, cy), bzn = std::min(kB, cz);
    bool ok = true;
    static constexpr int kX[kB] = {HierarchyBrick::Local(0, 0), HierarchyBrick::Local(0, 1),
                                   HierarchyBrick::Local(0, 2), HierarchyBrick::Local(0, 3),
                                   HierarchyBrick::Local(0, 4), HierarchyBrick::Local(0, 5),
                                   HierarchyBrick::Local(0, 6), HierarchyBrick::Local(0, 7)};
    for (int z = 0; z < kB; ++z)
      for (int y = 0; y < kB; ++y) {
        const int yz = HierarchyBrick::Local(2, z) + HierarchyBrick::Local(1, y);
        float* value = brick->value + yz;
        uint16_t* eta = brick->eta + yz;
        const int p = z * kTZ + y * kTY;
        const int inside = z < bzn && y < byn ? bxn : 0;
        for (int x = 0; x < inside; ++x) {
          value[kX[x]] = t[p + x];
          ok &= IsFinite(t[p + x]);
        }
        for (int x = inside; x < kB; ++x) value[kX[x]] = 0.0f;
        if ((z | y) & 1) {  // every x is scale 0
          for (int x = 0; x < inside; ++x) eta[kX[x]] = EncodeEtaRoundingUp(e[p + x]);
        } else {  // odd x only
          for (int x = 0; x < inside; ++x) eta[kX[x]] = x & 1 ? EncodeEtaRoundingUp(e[p + x]) : 0;
        }
        for (int x = inside; x < kB; ++x) eta[kX[x]] = 0;
        if (z & y & 1)
          for (int x = 1; x < inside; x += 2) s[z * sz + y * sy + x] = e[p + x];
      }
    return ok;
  }

  // Scale h >= 1: gathers the tile's lattice samples and the previous scale's cube centres
  // from the linear array, stores the scale's bfloat16 eta into the bricks and its cube
  // centres' float eta into the linear array.
  bool CoarseTile(int h, int tx, int ty, int tz) {
    const int u = 1 << h, half = u / 2;
    const int o[3] = {tx * (kT - 1) * u, ty * (kT - 1) * u, tz * (kT - 1) * u};  // origin
    int c[3], cq[3];
    for (int a = 0; a < 3; ++a) {
      c[a] = std::min(kT, ((last_ - o[a]) >> h) + 1);
      cq[a] = c[a] + 1;  // children at half-coordinates -1/2 .. c - 1/2
    }
    const size_t sy = size_t(n_), sz = size_t(n_) * n_;
    alignas(64) float t[kT * kT * kT];
    alignas(64) float e[kT * kT * kT];
    alignas(64) float q[kQ * kQ * kQ];
    // Prefetch as in FinestTile: the lattice points kAhead .. kAhead + 8 of each row, one per
    // cache line (16 floats).
    const int ahead = o[0] + (kAhead + kT - 1) * u <= last_ ? std::max(1, 16 / u) : 0;
    for (int z = 0; z < c[2]; ++z)
      for (int y = 0; y < c[1]; ++y) {
        const float* row = s_ + size_t(o[2] + z * u) * sz + size_t(o[1] + y * u) * sy + o[0];
        for (int x = 0; x < c[0]; ++x) t[z * kTZ + y * kTY + x] = row[x * u];
        if (ahead)
          for (int x = 0; x < kT; x += ahead) __builtin_prefetch(row + (kAhead + x) * u);
      }
    int qx0[kQ];  // x of child column i, or -1 outside the cube
    for (int i = 0; i < cq[0]; ++i) {
      const int x = o[0] + i * u - half;
      qx0[i] = x >= 0 && x <= last_ ? x : -1;
    }
    for (int z = 0; z < cq[2]; ++z)
      for (int y = 0; y < cq[1]; ++y) {
        float* dst = q + z * kQZ + y * kQY;
        const int cy = o[1] + y * u - half, cz = o[2] + z * u - half;
        if (cy < 0 || cy > last_ || cz < 0 || cz > last_) {
          std::fill(dst, dst + cq[0], 0.0f);
          continue;
        }
        const float* row = s_ + size_t(cz) * sz + size_t(cy) * sy;
        for (int x = 0; x < cq[0]; ++x) dst[x] = qx0[x] >= 0 ? row[qx0[x]] : 0.0f;
        if (ahead)
          for (int x = 0; x < kT; x += ahead)
            __builtin_prefetch(row + o[0] + (kAhead + x) * u - half);
      }
    TileEta<true>(c, t, q, e);

    // This tile's points: lattice coordinates 0..7 (the last plane is the next tile's).
    const int own[3] = {std::min(kT - 1, c[0]), std::min(kT - 1, c[1]), std::min(kT - 1, c[2])};
    HierarchyBrick* bricks = bricks_;
    for (int z = 0; z < own[2]; ++z)
      for (int y = 0; y < own[1]; ++y) {
        const int gy = o[1] + y * u, gz = o[2] + z * u;
        const uint64_t oyz = offset_[1][gy] + offset_[2][gz];
        const int p = z * kTZ + y * kTY;
        const bool yz_odd = (y | z) & 1;
        for (int x = yz_odd ? 0 : 1; x < own[0]; x += yz_odd ? 1 : 2) {
          const uint64_t i = offset_[0][o[0] + x * u] + oyz;
          bricks[i >> (3 * HierarchyBrick::kLog2)].eta[i & (HierarchyBrick::kPoints - 1)] =
              EncodeEtaRoundingUp(e[p + x]);
        }
        if (z & y & 1) {
          float* row = s_ + size_t(gz) * sz + size_t(gy) * sy + o[0];
          for (int x = 1; x < own[0]; x += 2) row[x * u] = e[p + x];
        }
      }
    return true;
  }

  int brick_count() const { return (n_ + HierarchyBrick::kMask) >> HierarchyBrick::kLog2; }

  float* s_;
  HierarchyBrick* bricks_;
  const uint64_t* offset_[3];
  int k_, n_, last_;
  const std::atomic<bool>* stop_ = nullptr;
};

template <typename F>
void Hierarchy::ForEachRow(F&& f) const {
  // One task per z plane of the linear output.
  tbb::parallel_for(tbb::blocked_range<int>(0, n_), [&](const tbb::blocked_range<int>& r) {
    for (int z = r.begin(); z != r.end(); ++z)
      for (int y = 0; y < n_; ++y) f(y, z, (size_t(z) * n_ + y) * n_);
  });
}

std::vector<float> Hierarchy::LinearSamples() const {
  std::vector<float> out(point_count());
  ForEachRow([&](int y, int z, size_t row) {
    for (int x = 0; x < n_; ++x) out[row + x] = sample(x, y, z);
  });
  return out;
}

std::vector<float> Hierarchy::LinearEta() const {
  std::vector<float> out(point_count());
  ForEachRow([&](int y, int z, size_t row) {
    for (int x = 0; x < n_; ++x) out[row + x] = eta(x, y, z);
  });
  return out;
}

UninitializedVector<uint16_t> Hierarchy::LinearEtaCodes() const {
  UninitializedVector<uint16_t> out(point_count());
  ForEachRow([&](int y, int z, size_t row) {
    for (int x = 0; x < n_; ++x) {
      const size_t i = index(x, y, z);
      out[row + x] = bricks_[i >> 9].eta[i & 511];
    }
  });
  return out;
}

UninitializedVector<uint16_t> Hierarchy::StoredEtaCodes() const {
  UninitializedVector<uint16_t> out(stored_point_count());
  const int sx = stored_[0], sy = stored_[1];
  tbb::parallel_for(tbb::blocked_range<int>(0, stored_[2]), [&](const tbb::blocked_range<int>& r) {
    for (int l = r.begin(); l != r.end(); ++l)
      for (int j = 0; j < sy; ++j) {
        uint16_t* row = &out[(size_t(l) * sy + j) * sx];
        for (int i = 0; i < sx; ++i) row[i] = bricks_[BrickOf(i, j, l)].eta[PlaceInBrick(i, j, l)];
      }
  });
  return out;
}

namespace {

absl::Status OutOfMemory(const PaddedSamples& samples) {
  double bricks = 1;
  for (int a = 0; a < 3; ++a)
    bricks *= double((size_t(samples.stored(a)) + HierarchyBrick::kMask) >> HierarchyBrick::kLog2);
  const double gib = bricks * sizeof(HierarchyBrick) / double(1 << 30);
  char size[32];
  std::snprintf(size, sizeof(size), "%.1f GiB", gib);
  return absl::ResourceExhaustedError("hierarchy: out of memory for the " +
                                      std::to_string(samples.n) + "^3 cube's store (" + size + ")");
}

bool ValidPlanes(const PaddedSamples& s) {
  if (s.whole_cube()) return true;
  for (int a = 0; a < 3; ++a) {
    const std::vector<int>& planes = s.planes[a];
    const std::vector<int>& of = s.plane_of[a];
    if (planes.empty() || of.size() != size_t(s.n)) return false;
    for (size_t i = 0; i < planes.size(); ++i)
      if (planes[i] < 0 || planes[i] >= s.n || (i > 0 && planes[i] <= planes[i - 1])) return false;
    for (const int p : of)
      if (p < 0 || size_t(p) >= planes.size()) return false;
  }
  return true;
}

}  // namespace

absl::Status Hierarchy::SetUpStore(const PaddedSamples& samples) {
  if (samples.k < 1 || samples.k > 12 || samples.n != (1 << samples.k) + 1 ||
      !ValidPlanes(samples) || samples.values.size() != samples.stored_points())
    return absl::InvalidArgumentError("hierarchy: samples are not a (2^k+1)^3 cube");
  k_ = samples.k;
  n_ = samples.n;
  data_dims_ = samples.data_dims;
  constexpr int b = HierarchyBrick::kLog2, m = HierarchyBrick::kMask;
  for (int a = 0; a < 3; ++a) {
    stored_[a] = samples.stored(a);
    bricks_per_axis_[a] = (size_t(stored_[a]) + m) >> b;
  }
  for (int a = 0; a < 3; ++a) {
    const size_t brick_stride = a == 0   ? 1
                                : a == 1 ? bricks_per_axis_[0]
                                         : bricks_per_axis_[0] * bricks_per_axis_[1];
    axis_offset_[a].resize(size_t(n_));
    value_bytes_[a].resize(size_t(n_));
    eta_bytes_[a].resize(size_t(n_));
    for (int c = 0; c < n_; ++c) {
      const int s = samples.stand_in(a, c);
      const size_t brick = size_t(s >> b) * brick_stride, inside = HierarchyBrick::Local(a, s & m);
      axis_offset_[a][c] = (brick << (3 * b)) | inside;
      value_bytes_[a][c] = brick * sizeof(HierarchyBrick) + inside * sizeof(float);
      eta_bytes_[a][c] = brick * sizeof(HierarchyBrick) + inside * sizeof(uint16_t) +
                         (a == 0 ? offsetof(HierarchyBrick, eta) : 0);
    }
  }
  // not initialised: the builder or the assembly writes all. Failing, it throws bad_alloc,
  // which BuildHierarchy and AssembleHierarchy turn into a status.
  bricks_.resize(bricks_per_axis_[0] * bricks_per_axis_[1] * bricks_per_axis_[2]);
  AdviseHugePages(bricks_.data(), bricks_.size() * sizeof(HierarchyBrick));
  return absl::OkStatus();
}

// An allocation that fails (the store, the large one; or any small one of a process at its
// memory limit) is a ResourceExhausted status for the caller, not a throw.
absl::StatusOr<HierarchyPtr> AssembleHierarchy(const PaddedSamples& samples,
                                               const EtaCodeSlabs& read_eta_codes) try {
  auto h = std::make_shared<Hierarchy>();
  ISOSTREAM_RETURN_IF_ERROR(h->SetUpStore(samples));
  // Fill one layer of bricks (8 stored planes) at a time, brick by brick (each written once,
  // whole, by one thread, which also first-touches its pages). Points of partial bricks beyond
  // the stored planes are never read; they get zeros so the store is deterministic.
  constexpr int b = HierarchyBrick::kLog2, m = HierarchyBrick::kMask;
  const int sx = samples.stored(0), sy = samples.stored(1), sz = samples.stored(2);
  const size_t nbx = h->bricks_per_axis_[0], nby = h->bricks_per_axis_[1];
  const size_t nbz = h->bricks_per_axis_[2];
  const size_t plane = size_t(sx) * sy;
  HierarchyBrick* bricks = h->bricks_.data();
  UninitializedVector<uint16_t> slab(size_t(m + 1) * plane);
  for (size_t bz = 0; bz < nbz; ++bz) {
    const int z_begin = int(bz << b), z_end = std::min(sz, z_begin + m + 1);
    if (!read_eta_codes(z_begin, z_end, slab.data()))
      return absl::DataLossError("hierarchy: the eta codes of stored planes " +
                                 std::to_string(z_begin) + ".." + std::to_string(z_end - 1) +
                                 " could not be read");
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nby), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t by = r.begin(); by != r.end(); ++by) {
        for (size_t bx = 0; bx < nbx; ++bx) {
          HierarchyBrick& brick = bricks[(bz * nby + by) * nbx + bx];
          for (int lz = 0; lz <= m; ++lz)
            for (int ly = 0; ly <= m; ++ly) {
              const int z = z_begin + lz, y = int(by << b) + ly, x0 = int(bx << b);
              const int local = HierarchyBrick::Local(2, lz) + HierarchyBrick::Local(1, ly);
              const int inside = z < sz && y < sy ? std::max(0, std::min(m + 1, sx - x0)) : 0;
              const size_t row = (size_t(z) * sy + y) * sx + x0;
              const size_t slab_row = (size_t(lz) * sy + y) * sx + x0;
              if (inside == m + 1) {
                // A whole row (all but the last): unrolled, the x placements are constants (~1 G
                // instructions less at 513^3 than computing each).
#pragma GCC unroll 8
                for (int lx = 0; lx <= m; ++lx) {
                  brick.value[local + HierarchyBrick::Local(0, lx)] = samples.values[row + lx];
                  brick.eta[local + HierarchyBrick::Local(0, lx)] = slab[slab_row + lx];
                }
                continue;
              }
              for (int lx = 0; lx < inside; ++lx) {
                brick.value[local + HierarchyBrick::Local(0, lx)] = samples.values[row + lx];
                brick.eta[local + HierarchyBrick::Local(0, lx)] = slab[slab_row + lx];
              }
              for (int lx = inside; lx <= m; ++lx) {
                brick.value[local + HierarchyBrick::Local(0, lx)] = 0.0f;
                brick.eta[local + HierarchyBrick::Local(0, lx)] = 0;
              }
            }
        }
      }
    });
  }
  return HierarchyPtr(std::move(h));
} catch (const std::bad_alloc&) {
  return OutOfMemory(samples);
}

absl::StatusOr<HierarchyPtr> BuildHierarchy(PaddedSamples samples,
                                            const HierarchyBuildOptions& options) try {
  auto h = std::make_shared<Hierarchy>();
  ISOSTREAM_RETURN_IF_ERROR(h->SetUpStore(samples));
  tbb::task_arena arena(ArenaSize(options.threads));
  bool finite = true;
  if (samples.whole_cube()) {
    HierarchyBuilder builder(samples.k, samples.values.data(), h.get());
    arena.execute([&] { finite = builder.Run(options); });
  } else {
    arena.execute([&] { finite = BuildWithStandIns(&samples, h.get(), options); });
  }
  // Before the finite check: a stopped build left tiles unwritten, not samples wrong.
  if (options.stop && options.stop->load()) return absl::CancelledError("hierarchy build stopped");
  if (!finite) return absl::InvalidArgumentError("hierarchy: non-finite sample");
  return HierarchyPtr(std::move(h));
} catch (const std::bad_alloc&) {
  return OutOfMemory(samples);
}

}  // namespace isostream
