// eta where stand-ins hold the planes deep in the padding: hierarchy.cpp's definition evaluated
// point by point over the stored points, the samples at refinement-edge ends and the children's
// eta read through the stand-in maps (a coordinate whose plane is not stored reads its
// stand-in's, which holds the same sample and eta: stored_planes.h). The arithmetic and the
// order of the scales and kinds are the whole cube's builder's, so every cube point reads the
// same bits from either store (tests/unit/hierarchy_stand_in_test.cpp).
//
// The samples' array is the scratch, as in the whole cube's builder: a point's sample is read
// by its own wavelet and by finer points' (whose refinement edges end at coarser points), so
// once its own eta is known nothing reads the sample again, and the float eta overwrites it.
// Points are done scale by scale from the finest, and within a scale edge centres, then face
// centres, then cube centres, each kind reading only the kinds done before it.
#include "server/hierarchy/stand_in_build.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <vector>

#include "server/hierarchy/eta_rounding.h"

namespace isostream {

using hierarchy_internal::DiamondEta;
using hierarchy_internal::IsFinite;

class StandInBuilder {
 public:
  StandInBuilder(PaddedSamples* s, Hierarchy* h)
      : s_(*s), h_(*h), v_(s->values.data()), last_(1 << s->k) {
    for (int a = 0; a < 3; ++a) {
      planes_[a] = s->planes[a].data();
      of_[a] = s->plane_of[a].data();
      stored_[a] = s->stored(a);
    }
    stride_[0] = 1;
    stride_[1] = stored_[0];
    stride_[2] = int64_t(stored_[0]) * stored_[1];
  }

  bool Run(const HierarchyBuildOptions& options) {
    stop_ = options.stop;
    if (!CopySamples()) return false;
    for (int h = 0; h < s_.k && !Stopped(); ++h) {
      Scale(h);
      if (options.progress) options.progress(std::min(0.99, double(h + 1) / s_.k));
    }
    if (Stopped()) return true;  // the caller reports the stop
    StoreEta();
    if (options.progress) options.progress(1.0);
    return true;
  }

 private:
  bool Stopped() const { return stop_ && stop_->load(std::memory_order_relaxed); }

  // Every brick whole: the samples, eta 0 for now (the 8 cube corners keep it), zeros beyond
  // the stored planes so the store is deterministic. One layer of bricks per task.
  bool CopySamples() {
    constexpr int b = HierarchyBrick::kLog2;
    std::atomic<bool> finite{true};
    const size_t layers = h_.bricks_per_axis_[2];
    const size_t layer = h_.bricks_per_axis_[0] * h_.bricks_per_axis_[1];
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, layers), [&](const tbb::blocked_range<size_t>& r) {
          bool ok = true;
          for (size_t bz = r.begin(); bz != r.end() && !Stopped(); ++bz) {
            std::memset(static_cast<void*>(&h_.bricks_[bz * layer]), 0,
                        layer * sizeof(HierarchyBrick));
            const int l_end = std::min(stored_[2], int((bz + 1) << b));
            for (int l = int(bz << b); l < l_end; ++l)
              for (int j = 0; j < stored_[1]; ++j) {
                const float* row = v_ + (size_t(l) * stored_[1] + j) * stored_[0];
                for (int i = 0; i < stored_[0]; ++i) {
                  h_.bricks_[h_.BrickOf(i, j, l)].value[Hierarchy::PlaceInBrick(i, j, l)] = row[i];
                  ok &= IsFinite(row[i]);
                }
              }
          }
          if (!ok) finite.store(false, std::memory_order_relaxed);
        });
    return finite.load();
  }

  // The points of scale h (every coordinate a multiple of u = 2^h, some an odd one): per axis
  // the stored planes whose coordinate is an odd multiple of u, and those of coarser scales.
  void Scale(int h) {
    const int u = 1 << h;
    std::vector<int> odd[3], even[3];
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < stored_[a]; ++i) {
        const int c = planes_[a][i];
        if (c % u != 0) continue;
        ((c / u) & 1 ? odd[a] : even[a]).push_back(c);
      }
    // Edge centres (one odd axis), face centres (two), cube centres (three): axis a is odd
    // where bit a of the mask is set.
    Pass<1>(h, odd, even);
    Pass<2>(h, odd, even);
    Pass<4>(h, odd, even);
    Pass<3>(h, odd, even);
    Pass<5>(h, odd, even);
    Pass<6>(h, odd, even);
    Pass<7>(h, odd, even);
  }

  template <unsigned kMask>
  void Pass(int h, const std::vector<int> odd[3], const std::vector<int> even[3]) {
    const std::vector<int>* on[3];
    for (int a = 0; a < 3; ++a) on[a] = (kMask >> a) & 1 ? &odd[a] : &even[a];
    if (on[0]->empty() || on[1]->empty() || on[2]->empty()) return;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, on[2]->size()),
                      [&](const tbb::blocked_range<size_t>& r) {
                        for (size_t iz = r.begin(); iz != r.end() && !Stopped(); ++iz)
                          for (const int y : *on[1])
                            for (const int x : *on[0]) Point<kMask>(h, {x, y, (*on[2])[iz]});
                      });
  }

  // EvenEndSign in lattice units: which way the refinement edge of an odd coordinate runs.
  static int Sign(int lattice) { return (lattice & 3) == 3 ? 1 : -1; }

  // How far the samples' array moves when cube coordinate c moves by delta along `axis`.
  int64_t Step(int axis, int c, int delta) const {
    return (int64_t(of_[axis][c + delta]) - of_[axis][c]) * stride_[axis];
  }

  template <unsigned kMask>
  void Point(int h, const std::array<int, 3>& p) {
    constexpr int kKind = __builtin_popcount(kMask);
    const int u = 1 << h;
    const int64_t at =
        (int64_t(of_[2][p[2]]) * stored_[1] + of_[1][p[1]]) * stored_[0] + of_[0][p[0]];
    // The refinement edge (p - d, p + d): along the odd axis for an edge centre, else one step
    // of the lattice along every odd axis, in EvenEndSign's direction.
    int64_t plus = 0, minus = 0;
    for (int a = 0; a < 3; ++a) {
      if (!((kMask >> a) & 1)) continue;
      const int d = kKind == 1 ? u : Sign(p[a] >> h) * u;
      plus += Step(a, p[a], d);
      minus += Step(a, p[a], -d);
    }
    float worst = 0;
    if constexpr (kKind == 1) {
      // The previous scale's cube centres half a step away on every axis, inside the cube.
      if (h > 0) {
        const int half = u / 2;
        int64_t step[3][2];
        bool inside[3][2];
        for (int a = 0; a < 3; ++a) {
          inside[a][0] = p[a] - half >= 0;
          inside[a][1] = p[a] + half <= last_;
          step[a][0] = inside[a][0] ? Step(a, p[a], -half) : 0;
          step[a][1] = inside[a][1] ? Step(a, p[a], half) : 0;
        }
        for (int sz = 0; sz < 2; ++sz)
          for (int sy = 0; sy < 2; ++sy)
            for (int sx = 0; sx < 2; ++sx)
              if (inside[0][sx] && inside[1][sy] && inside[2][sz])
                worst = std::max(worst, v_[at + step[0][sx] + step[1][sy] + step[2][sz]]);
      }
    } else {
      // Face centres: the edge centres one step along each odd axis; cube centres: the face
      // centres one step along each axis.
      for (int a = 0; a < 3; ++a) {
        if (!((kMask >> a) & 1)) continue;
        worst = std::max(worst, v_[at + Step(a, p[a], -u)]);
        worst = std::max(worst, v_[at + Step(a, p[a], u)]);
      }
    }
    v_[at] = DiamondEta(v_[at], v_[at + plus], v_[at + minus], worst);
  }

  // The float eta of every stored point but the cube's corners, rounded up to bfloat16, into
  // the bricks.
  void StoreEta() {
    tbb::parallel_for(
        tbb::blocked_range<int>(0, stored_[2]), [&](const tbb::blocked_range<int>& r) {
          for (int l = r.begin(); l != r.end(); ++l) {
            const bool z_corner = planes_[2][l] == 0 || planes_[2][l] == last_;
            for (int j = 0; j < stored_[1]; ++j) {
              const bool yz_corner = z_corner && (planes_[1][j] == 0 || planes_[1][j] == last_);
              const float* row = v_ + (size_t(l) * stored_[1] + j) * stored_[0];
              for (int i = 0; i < stored_[0]; ++i) {
                if (yz_corner && (planes_[0][i] == 0 || planes_[0][i] == last_)) continue;
                h_.bricks_[h_.BrickOf(i, j, l)].eta[Hierarchy::PlaceInBrick(i, j, l)] =
                    EncodeEtaRoundingUp(row[i]);
              }
            }
          }
        });
  }

  PaddedSamples& s_;
  Hierarchy& h_;
  float* v_;
  const int* planes_[3];
  const int* of_[3];
  int stored_[3];
  int64_t stride_[3];  // of a stored plane index along each axis in the samples' array
  int last_;
  const std::atomic<bool>* stop_ = nullptr;
};

bool BuildWithStandIns(PaddedSamples* samples, Hierarchy* h, const HierarchyBuildOptions& options) {
  StandInBuilder builder(samples, h);
  return builder.Run(options);
}

}  // namespace isostream
