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
// recursion over the tree). The builder touches no memory beyond the bricks it returns:
//  * Scale 0 (7/8 of the points) in one pass over the bricks. Its diamonds reach one point
//    each way, so each brick's scale-0 eta follows from its 8^3 samples plus the first plane
//    of the next brick on each axis (a 9^3 tile, in L1): the pass writes each brick whole
//    (samples and eta, first touch of its pages) and computes scale 0 in the tile.
//  * Scales 1..k-1 (1/8 of the points) by per-sub-lattice stencil passes over the linear
//    samples, in place: a point's float eta overwrites its sample. That is safe because a
//    diamond reads the samples of its refinement edge's ends, which are coarser points (still
//    samples: the ends of a scale-h edge are multiples of 2^(h+1) on every axis), and the eta
//    of its children, finer points already overwritten; the brick store already holds the
//    samples. Scale 0 leaves its cube centres' float eta in the linear array for the scale-1
//    edges. Each pass also stores its points' bfloat16 eta into the bricks.
#include "server/hierarchy/hierarchy.h"

#include <sys/mman.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>

#include "server/hierarchy/refinement_vertex.h"

namespace isostream {
namespace {

// Large buffers are first touched by the parallel passes; asking for transparent huge pages
// cuts the page faults of a 513^3 build from ~330 k to ~650 (the kernel zeroing each page
// was a third to a half of the build time). Only a hint: ignored where THP is off.
void AdviseHugePages(void* data, size_t bytes) {
  constexpr uintptr_t kHuge = uintptr_t{2} << 20;
  const uintptr_t begin = (reinterpret_cast<uintptr_t>(data) + kHuge - 1) & ~(kHuge - 1);
  const uintptr_t end = (reinterpret_cast<uintptr_t>(data) + bytes) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
}

// The smallest float >= v (v >= 0). For f >= +0 the next float up is the next bit pattern
// (std::nextafter(f, INFINITY), without the library call).
inline float RoundUp(double v) {
  float f = static_cast<float>(v);
  if (static_cast<double>(f) < v) {
    uint32_t bits;
    std::memcpy(&bits, &f, sizeof(bits));
    ++bits;
    std::memcpy(&f, &bits, sizeof(f));
  }
  return f;
}

// eta of a scale-0 diamond at t[p] with refinement edge (p - d, p + d) and no children (an
// edge centre), or with children whose eta is `worst`.
inline float Eta(const float* t, int p, int d, float worst) {
  const double w = static_cast<double>(t[p]) - 0.5 * (static_cast<double>(t[p + d]) + t[p - d]);
  return RoundUp(std::fabs(w) + worst);
}

inline bool IsFinite(float v) {
  uint32_t bits;
  std::memcpy(&bits, &v, sizeof(bits));
  return (bits & 0x7f800000u) != 0x7f800000u;
}

}  // namespace

class HierarchyBuilder {
 public:
  // `samples`: the linear (x fastest) cube, consumed (overwritten with float eta from scale 1
  // on). `h`: laid out (SetUpStore), bricks not yet written.
  HierarchyBuilder(int k, float* samples, Hierarchy* h)
      : s_(samples),
        bricks_(h->bricks_.data()),
        offset_{h->axis_offset_[0].data(), h->axis_offset_[1].data(), h->axis_offset_[2].data()},
        k_(k),
        n_((1 << k) + 1),
        last_(1 << k) {}

  // False if a sample is not finite (then eta is meaningless and the build is abandoned).
  bool Run(const HierarchyBuildOptions& options) {
    const size_t total = size_t(n_) * n_ * n_;
    const bool report = options.progress && total > (size_t{1} << 24);
    if (!FinestScale()) return false;
    const size_t coarse = size_t(n_ / 2 + 1) * (n_ / 2 + 1) * (n_ / 2 + 1);
    size_t done = total - coarse;
    if (report) options.progress(std::min(0.99, static_cast<double>(done) / total));
    for (int h = 1; h < k_; ++h) {
      for (DiamondKind kind : {DiamondKind::kEdge, DiamondKind::kFace, DiamondKind::kCube}) {
        for (int mask = 1; mask < 8; ++mask) {
          if (3 - __builtin_popcount(static_cast<unsigned>(mask)) != static_cast<int>(kind))
            continue;
          done += Pass(h, mask, kind);
        }
      }
      if (report) options.progress(std::min(0.99, static_cast<double>(done) / total));
    }
    if (report) options.progress(1.0);
    return true;
  }

 private:
  static constexpr int kB = HierarchyBrick::kMask + 1;  // brick side, 8
  static constexpr int kT = kB + 1;                     // tile side, 9
  static constexpr int kTY = kT, kTZ = kT * kT;         // tile strides

  // Scale 0, brick by brick (one brick row per task: its tiles are consecutive in the linear
  // samples, its bricks consecutive in the store).
  bool FinestScale() {
    const int nb = (n_ + kB - 1) / kB;
    std::atomic<bool> finite{true};
    tbb::parallel_for(tbb::blocked_range<int>(0, nb * nb), [&](const tbb::blocked_range<int>& r) {
      bool ok = true;
      for (int zy = r.begin(); zy != r.end(); ++zy)
        for (int bx = 0; bx < nb; ++bx)
          ok &= FinestBrick(bx, zy % nb, zy / nb, &bricks_[size_t(zy) * nb + bx]);
      if (!ok) finite.store(false, std::memory_order_relaxed);
    });
    return finite.load();
  }

  // One brick: tile t = samples at brick-local 0..8 per axis (clipped to the cube), e = their
  // scale-0 eta. Cube sizes are odd and bricks start at multiples of 8, so the clipped tile
  // sides c[] are odd: every odd (scale-0) coordinate c < c[a] has both neighbours c +- 1 in
  // the tile, and a scale-0 diamond's refinement-edge ends and children are such neighbours.
  // Local coordinates are congruent to global ones mod 8, so the edge directions
  // (EvenEndSign) read the same.
  bool FinestBrick(int bx, int by, int bz, HierarchyBrick* brick) {
    const int x0 = bx * kB, y0 = by * kB, z0 = bz * kB;
    const int cx = std::min(kT, n_ - x0), cy = std::min(kT, n_ - y0), cz = std::min(kT, n_ - z0);
    alignas(64) float t[kT * kT * kT];
    alignas(64) float e[kT * kT * kT];
    const size_t sy = size_t(n_), sz = size_t(n_) * n_;
    const float* src = s_ + z0 * sz + y0 * sy + x0;
    for (int z = 0; z < cz; ++z)
      for (int y = 0; y < cy; ++y)
        std::memcpy(t + z * kTZ + y * kTY, src + z * sz + y * sy, sizeof(float) * cx);

    auto sign = [](int c) { return ((c & 3) == 3) ? 1 : -1; };  // EvenEndSign at scale 0
    // Edge centres: one odd coordinate; no children.
    for (int z = 0; z < cz; z += 2)
      for (int y = 0; y < cy; y += 2) {
        for (int x = 1; x < cx; x += 2) {
          const int p = z * kTZ + y * kTY + x;
          e[p] = Eta(t, p, 1, 0.0f);
        }
        if (y + 1 < cy)
          for (int x = 0; x < cx; x += 2) {
            const int p = z * kTZ + (y + 1) * kTY + x;
            e[p] = Eta(t, p, kTY, 0.0f);
          }
        if (z + 1 < cz)
          for (int x = 0; x < cx; x += 2) {
            const int p = (z + 1) * kTZ + y * kTY + x;
            e[p] = Eta(t, p, kTZ, 0.0f);
          }
      }
    // Face centres: two odd coordinates; children the 4 edge centres +-1 along them.
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
    // Cube centres: all odd (inside the brick); children the 6 face centres +-1.
    for (int z = 1; z < cz; z += 2)
      for (int y = 1; y < cy; y += 2)
        for (int x = 1; x < cx; x += 2) {
          const int p = z * kTZ + y * kTY + x;
          const float worst =
              std::max(std::max(std::max(e[p - 1], e[p + 1]), std::max(e[p - kTY], e[p + kTY])),
                       std::max(e[p - kTZ], e[p + kTZ]));
          e[p] = Eta(t, p, sign(x) + sign(y) * kTY + sign(z) * kTZ, worst);
        }

    // The brick, whole: samples, scale-0 eta, 0 for the coarser points (their passes come
    // later) and for points beyond the cube (never read; zeros keep the store deterministic).
    // Cube centres keep their float eta in the linear array for the scale-1 edges.
    bool ok = true;
    const int bxn = std::min(kB, cx), byn = std::min(kB, cy), bzn = std::min(kB, cz);
    float* dst = s_ + z0 * sz + y0 * sy + x0;
    for (int z = 0; z < kB; ++z)
      for (int y = 0; y < kB; ++y) {
        float* value = brick->value + (z * kB + y) * kB;
        uint16_t* eta = brick->eta + (z * kB + y) * kB;
        const int p = z * kTZ + y * kTY;
        const int inside = z < bzn && y < byn ? bxn : 0;
        for (int x = 0; x < inside; ++x) {
          value[x] = t[p + x];
          ok &= IsFinite(t[p + x]);
        }
        for (int x = inside; x < kB; ++x) value[x] = 0.0f;
        if ((z | y) & 1) {  // every x is scale 0
          for (int x = 0; x < inside; ++x) eta[x] = EncodeEtaRoundingUp(e[p + x]);
        } else {  // odd x only
          for (int x = 0; x < inside; ++x) eta[x] = x & 1 ? EncodeEtaRoundingUp(e[p + x]) : 0;
        }
        for (int x = inside; x < kB; ++x) eta[x] = 0;
        if (z & y & 1)
          for (int x = 1; x < inside; x += 2) dst[z * sz + y * sy + x] = e[p + x];
      }
    return ok;
  }

  // One sub-lattice of scale h >= 1: points whose odd axes (in units of 2^h) are `mask`.
  // Returns the point count.
  size_t Pass(int h, int mask, DiamondKind kind) {
    switch (mask) {
      case 1:
        return PassT<1>(h, kind);
      case 2:
        return PassT<2>(h, kind);
      case 3:
        return PassT<3>(h, kind);
      case 4:
        return PassT<4>(h, kind);
      case 5:
        return PassT<5>(h, kind);
      case 6:
        return PassT<6>(h, kind);
      default:
        return PassT<7>(h, kind);
    }
  }

  // Specialised per odd-axis mask so the inner loop is a fixed stencil over a plain array.
  // Along an odd axis the sign of the refinement edge alternates with the lattice index
  // (coordinates u, 3u, 5u, ... are 1, 3, 1, ... mod 4 in units of u).
  template <int kMask>
  size_t PassT(int h, DiamondKind kind) {
    constexpr bool kOdd[3] = {(kMask & 1) != 0, (kMask & 2) != 0, (kMask & 4) != 0};
    const int u = 1 << h, step = 2 * u;
    int start[3], count[3];
    for (int a = 0; a < 3; ++a) {
      start[a] = kOdd[a] ? u : 0;
      count[a] = kOdd[a] ? (last_ >> (h + 1)) : (last_ >> (h + 1)) + 1;
    }
    float* s = s_;  // samples at coarser points, eta at finer ones (see the top)
    const ptrdiff_t sy = n_, sz = static_cast<ptrdiff_t>(n_) * n_;
    const ptrdiff_t stride[3] = {1, sy, sz};

    // Children that need no bounds check: cube and face centres only have children inside
    // their own cell. Edge centres have 8 diagonal children, some of which fall outside the
    // domain when the edge lies on the boundary; those points take the checked path.
    ptrdiff_t child[8];
    int child_count = 0;
    if (kind == DiamondKind::kCube || kind == DiamondKind::kFace) {
      for (int a = 0; a < 3; ++a)
        if (kind == DiamondKind::kCube || kOdd[a]) {
          child[child_count++] = u * stride[a];
          child[child_count++] = -u * stride[a];
        }
    } else {
      const int half = u / 2;
      for (int c = 0; c < 8; ++c)
        child[child_count++] = ((c & 1) ? half : -half) + ((c & 2) ? half : -half) * sy +
                               ((c & 4) ? half : -half) * sz;
    }
    const bool edge_children = kind == DiamondKind::kEdge;
    HierarchyBrick* bricks = bricks_;
    const uint32_t* ox = offset_[0];

    const int rows = count[1] * count[2];
    tbb::parallel_for(tbb::blocked_range<int>(0, rows, 16), [&](const tbb::blocked_range<int>& r) {
      for (int row = r.begin(); row != r.end(); ++row) {
        const int iy = row % count[1], iz = row / count[1];
        const int y = start[1] + iy * step, z = start[2] + iz * step;
        ptrdiff_t edge_yz = 0;
        if (kOdd[1]) edge_yz += EvenEndSign(y, h) * u * sy;
        if (kOdd[2]) edge_yz += EvenEndSign(z, h) * u * sz;
        const bool row_on_boundary = edge_children && ((!kOdd[1] && (y == 0 || y == last_)) ||
                                                       (!kOdd[2] && (z == 0 || z == last_)));
        const uint32_t oyz = offset_[1][y] + offset_[2][z];
        ptrdiff_t p = start[0] + y * sy + z * sz;
        for (int ix = 0, x = start[0]; ix < count[0]; ++ix, x += step, p += step) {
          const ptrdiff_t e = kOdd[0] ? edge_yz + ((ix & 1) ? u : -u) : edge_yz;
          const double w =
              static_cast<double>(s[p]) - 0.5 * (static_cast<double>(s[p + e]) + s[p - e]);
          float worst = 0.0f;
          const bool checked =
              row_on_boundary || (edge_children && !kOdd[0] && (ix == 0 || ix == count[0] - 1));
          if (checked) {
            const int c[3] = {x, y, z};
            worst = EdgeChildren(c, h, p, s, stride);
          } else {
            for (int i = 0; i < child_count; ++i) worst = std::max(worst, s[p + child[i]]);
          }
          const float eta = RoundUp(std::fabs(w) + worst);
          s[p] = eta;
          const uint32_t i = ox[x] + oyz;
          bricks[i >> (3 * HierarchyBrick::kLog2)].eta[i & (HierarchyBrick::kPoints - 1)] =
              EncodeEtaRoundingUp(eta);
        }
      }
    });
    return static_cast<size_t>(count[0]) * count[1] * count[2];
  }

  float EdgeChildren(const int c[3], int h, ptrdiff_t p, const float* eta,
                     const ptrdiff_t stride[3]) const {
    const int half = 1 << (h - 1);
    float worst = 0.0f;
    for (int s = 0; s < 8; ++s) {
      ptrdiff_t off = 0;
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        const int d = (s >> a) & 1 ? half : -half;
        const int q = c[a] + d;
        inside &= q >= 0 && q <= last_;
        off += d * stride[a];
      }
      if (inside) worst = std::max(worst, eta[p + off]);
    }
    return worst;
  }

  float* s_;
  HierarchyBrick* bricks_;
  const uint32_t* offset_[3];
  int k_, n_, last_;
};

template <typename F>
void Hierarchy::ForEachRow(F&& f) const {
  // Rows of 8 points along x inside one brick line up with 8 linear samples.
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

absl::Status Hierarchy::SetUpStore(const PaddedSamples& samples) {
  const size_t n = static_cast<size_t>(samples.n);
  if (samples.k < 1 || samples.k > 12 || samples.n != (1 << samples.k) + 1 ||
      samples.values.size() != n * n * n)
    return absl::InvalidArgumentError("hierarchy: samples are not a (2^k+1)^3 cube");
  k_ = samples.k;
  n_ = samples.n;
  data_dims_ = samples.data_dims;
  const size_t nb = (n + HierarchyBrick::kMask) >> HierarchyBrick::kLog2;  // bricks per axis
  constexpr int b = HierarchyBrick::kLog2, m = HierarchyBrick::kMask;
  for (int a = 0; a < 3; ++a) {
    const size_t brick_stride = a == 0 ? 1 : a == 1 ? nb : nb * nb;
    axis_offset_[a].resize(n);
    for (size_t c = 0; c < n; ++c)
      axis_offset_[a][c] = uint32_t((((c >> b) * brick_stride) << (3 * b)) | ((c & m) << (a * b)));
  }
  bricks_.resize(nb * nb * nb);  // not initialised: the builder or the assembly writes all
  AdviseHugePages(bricks_.data(), bricks_.size() * sizeof(HierarchyBrick));
  return absl::OkStatus();
}

absl::StatusOr<HierarchyPtr> AssembleHierarchy(PaddedSamples samples,
                                               const UninitializedVector<uint16_t>& eta_codes) {
  auto h = std::make_shared<Hierarchy>();
  ISOSTREAM_RETURN_IF_ERROR(h->SetUpStore(samples));
  if (eta_codes.size() != samples.values.size())
    return absl::InvalidArgumentError("hierarchy: eta size does not match the samples");
  // Fill brick by brick (each written once, whole, by one thread, which also first-touches
  // its pages). Points of partial bricks beyond the cube are never read; they get zeros so
  // the store is deterministic.
  const size_t n = static_cast<size_t>(samples.n);
  const size_t nb = (n + HierarchyBrick::kMask) >> HierarchyBrick::kLog2;
  constexpr int b = HierarchyBrick::kLog2, m = HierarchyBrick::kMask;
  HierarchyBrick* bricks = h->bricks_.data();
  const int cube = samples.n;
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, nb * nb), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t zy = r.begin(); zy != r.end(); ++zy) {
          const int bz = int(zy / nb), by = int(zy % nb);
          for (size_t bx = 0; bx < nb; ++bx) {
            HierarchyBrick& brick = bricks[zy * nb + bx];
            for (int lz = 0; lz <= m; ++lz)
              for (int ly = 0; ly <= m; ++ly) {
                const int z = (bz << b) + lz, y = (by << b) + ly, x0 = int(bx << b);
                const int local = (lz << (2 * b)) | (ly << b);
                const int inside =
                    z < cube && y < cube ? std::max(0, std::min(m + 1, cube - x0)) : 0;
                const size_t row = (size_t(z) * n + y) * n + x0;
                for (int lx = 0; lx < inside; ++lx) {
                  brick.value[local + lx] = samples.values[row + lx];
                  brick.eta[local + lx] = eta_codes[row + lx];
                }
                for (int lx = inside; lx <= m; ++lx) {
                  brick.value[local + lx] = 0.0f;
                  brick.eta[local + lx] = 0;
                }
              }
          }
        }
      });
  return HierarchyPtr(std::move(h));
}

absl::StatusOr<HierarchyPtr> BuildHierarchy(PaddedSamples samples,
                                            const HierarchyBuildOptions& options) {
  auto h = std::make_shared<Hierarchy>();
  ISOSTREAM_RETURN_IF_ERROR(h->SetUpStore(samples));
  tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
  HierarchyBuilder builder(samples.k, samples.values.data(), h.get());
  bool finite = true;
  arena.execute([&] { finite = builder.Run(options); });
  if (!finite) return absl::InvalidArgumentError("hierarchy: non-finite sample");
  return HierarchyPtr(std::move(h));
}

}  // namespace isostream
