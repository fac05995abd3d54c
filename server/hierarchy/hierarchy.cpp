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
#include "server/hierarchy/hierarchy.h"

#include <sys/mman.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
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

float RoundUp(double v) {
  float f = static_cast<float>(v);
  if (static_cast<double>(f) < v) f = std::nextafter(f, INFINITY);
  return f;
}

}  // namespace

class HierarchyBuilder {
 public:
  // Linear arrays, x fastest: the stencils below are fixed offsets there.
  HierarchyBuilder(int k, const float* f, float* eta)
      : f_(f), eta_(eta), k_(k), n_((1 << k) + 1), last_(1 << k) {}

  void Run(const HierarchyBuildOptions& options) {
    const size_t total = size_t(n_) * n_ * n_;
    // Every point but the 8 corners is written by exactly one pass (first touch in parallel).
    for (int c = 0; c < 8; ++c)
      eta_[((c & 4) ? last_ : 0) * size_t(n_) * n_ + ((c & 2) ? last_ : 0) * size_t(n_) +
           ((c & 1) ? last_ : 0)] = 0;
    size_t done = 0;
    for (int h = 0; h < k_; ++h) {
      for (DiamondKind kind : {DiamondKind::kEdge, DiamondKind::kFace, DiamondKind::kCube}) {
        for (int mask = 1; mask < 8; ++mask) {
          if (3 - __builtin_popcount(static_cast<unsigned>(mask)) != static_cast<int>(kind))
            continue;
          done += Pass(h, mask, kind);
        }
      }
      if (options.progress && total > (size_t{1} << 24))
        options.progress(std::min(0.99, static_cast<double>(done) / total));
    }
    if (options.progress && total > (size_t{1} << 24)) options.progress(1.0);
  }

 private:
  // One sub-lattice: points of scale h whose odd axes are `mask`. Returns the point count.
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

  // Specialised per odd-axis mask so the inner loop is a fixed stencil over plain arrays.
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
    const float* f = f_;
    float* eta = eta_;
    const ptrdiff_t sy = n_, sz = static_cast<ptrdiff_t>(n_) * n_;
    const ptrdiff_t stride[3] = {1, sy, sz};

    // Children that need no bounds check: cube and face centres only have children inside
    // their own cell. Edge centres (h > 0) have 8 diagonal children, some of which fall outside
    // the domain when the edge lies on the boundary; those points take the checked path.
    ptrdiff_t child[8];
    int child_count = 0;
    if (kind == DiamondKind::kCube || kind == DiamondKind::kFace) {
      for (int a = 0; a < 3; ++a)
        if (kind == DiamondKind::kCube || kOdd[a]) {
          child[child_count++] = u * stride[a];
          child[child_count++] = -u * stride[a];
        }
    } else if (h > 0) {
      const int half = u / 2;
      for (int s = 0; s < 8; ++s)
        child[child_count++] = ((s & 1) ? half : -half) + ((s & 2) ? half : -half) * sy +
                               ((s & 4) ? half : -half) * sz;
    }
    const bool edge_children = kind == DiamondKind::kEdge && h > 0;

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
        ptrdiff_t p = start[0] + y * sy + z * sz;
        for (int ix = 0; ix < count[0]; ++ix, p += step) {
          const ptrdiff_t e = kOdd[0] ? edge_yz + ((ix & 1) ? u : -u) : edge_yz;
          const double w =
              static_cast<double>(f[p]) - 0.5 * (static_cast<double>(f[p + e]) + f[p - e]);
          float worst = 0.0f;
          const bool checked =
              row_on_boundary || (edge_children && !kOdd[0] && (ix == 0 || ix == count[0] - 1));
          if (checked) {
            const int c[3] = {start[0] + ix * step, y, z};
            worst = EdgeChildren(c, h, p, eta, stride);
          } else {
            for (int i = 0; i < child_count; ++i) worst = std::max(worst, eta[p + child[i]]);
          }
          eta[p] = RoundUp(std::fabs(w) + worst);
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

  const float* f_;
  float* eta_;
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

absl::StatusOr<HierarchyPtr> AssembleHierarchy(PaddedSamples samples,
                                               const UninitializedVector<float>& eta) {
  const size_t n = static_cast<size_t>(samples.n);
  if (samples.k < 1 || samples.k > 12 || samples.n != (1 << samples.k) + 1 ||
      samples.values.size() != n * n * n)
    return absl::InvalidArgumentError("hierarchy: samples are not a (2^k+1)^3 cube");
  if (eta.size() != samples.values.size())
    return absl::InvalidArgumentError("hierarchy: eta size does not match the samples");
  auto h = std::make_shared<Hierarchy>();
  h->k_ = samples.k;
  h->n_ = samples.n;
  h->data_dims_ = samples.data_dims;
  const size_t nb = (n + HierarchyBrick::kMask) >> HierarchyBrick::kLog2;  // bricks per axis
  constexpr int b = HierarchyBrick::kLog2, m = HierarchyBrick::kMask;
  for (int a = 0; a < 3; ++a) {
    const size_t brick_stride = a == 0 ? 1 : a == 1 ? nb : nb * nb;
    h->axis_offset_[a].resize(n);
    for (size_t c = 0; c < n; ++c)
      h->axis_offset_[a][c] =
          uint32_t((((c >> b) * brick_stride) << (3 * b)) | ((c & m) << (a * b)));
  }
  h->bricks_.resize(nb * nb * nb);
  AdviseHugePages(h->bricks_.data(), h->bricks_.size() * sizeof(HierarchyBrick));
  // Fill brick by brick (each written once, whole, by one thread, which also first-touches
  // its pages). Points of partial bricks beyond the cube are never read; they get zeros so
  // the store is deterministic.
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
                  brick.eta[local + lx] = EncodeEtaRoundingUp(eta[row + lx]);
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
  const size_t n = static_cast<size_t>(samples.n);
  if (samples.k < 1 || samples.k > 12 || samples.n != (1 << samples.k) + 1 ||
      samples.values.size() != n * n * n)
    return absl::InvalidArgumentError("hierarchy: samples are not a (2^k+1)^3 cube");
  const bool finite = tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, samples.values.size()), true,
      [&](const tbb::blocked_range<size_t>& r, bool ok) {
        for (size_t i = r.begin(); ok && i != r.end(); ++i) ok = std::isfinite(samples.values[i]);
        return ok;
      },
      [](bool a, bool b) { return a && b; });
  if (!finite) return absl::InvalidArgumentError("hierarchy: non-finite sample");
  UninitializedVector<float> eta(samples.values.size());
  AdviseHugePages(eta.data(), eta.size() * sizeof(float));
  tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
  HierarchyBuilder builder(samples.k, samples.values.data(), eta.data());
  arena.execute([&] { builder.Run(options); });
  return AssembleHierarchy(std::move(samples), eta);
}

}  // namespace isostream
