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

  // The stored point standing for cube point (x, y, z), in the samples' array.
  size_t At(int x, int y, int z) const {
    return (size_t(of_[2][z]) * stored_[1] + of_[1][y]) * stored_[0] + of_[0][x];
  }

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
    for (const unsigned mask : {1u, 2u, 4u, 3u, 5u, 6u, 7u}) {
      const std::vector<int>* on[3];
      for (int a = 0; a < 3; ++a) on[a] = (mask >> a) & 1 ? &odd[a] : &even[a];
      if (on[0]->empty() || on[1]->empty() || on[2]->empty()) continue;
      const int kind = __builtin_popcount(mask);
      tbb::parallel_for(tbb::blocked_range<size_t>(0, on[2]->size()),
                        [&](const tbb::blocked_range<size_t>& r) {
                          for (size_t iz = r.begin(); iz != r.end() && !Stopped(); ++iz)
                            for (const int y : *on[1])
                              for (const int x : *on[0]) Point(h, kind, mask, {x, y, (*on[2])[iz]});
                        });
    }
  }

  // EvenEndSign in lattice units: which way the refinement edge of an odd coordinate runs.
  static int Sign(int lattice) { return (lattice & 3) == 3 ? 1 : -1; }

  void Point(int h, int kind, unsigned mask, const std::array<int, 3>& p) {
    const int u = 1 << h;
    // The refinement edge (p - d, p + d): along the odd axis for an edge centre, else one step
    // of the lattice along every odd axis, in EvenEndSign's direction.
    int d[3] = {0, 0, 0};
    for (int a = 0; a < 3; ++a)
      if ((mask >> a) & 1) d[a] = kind == 1 ? u : Sign(p[a] >> h) * u;
    float worst = 0;
    if (kind == 1) {
      // The previous scale's cube centres half a step away on every axis, inside the cube.
      if (h > 0) {
        const int half = u / 2;
        for (int dz = -half; dz <= half; dz += u)
          for (int dy = -half; dy <= half; dy += u)
            for (int dx = -half; dx <= half; dx += u) {
              const int x = p[0] + dx, y = p[1] + dy, z = p[2] + dz;
              if (x < 0 || y < 0 || z < 0 || x > last_ || y > last_ || z > last_) continue;
              worst = std::max(worst, v_[At(x, y, z)]);
            }
      }
    } else {
      // Face centres: the edge centres one step along each odd axis; cube centres: the face
      // centres one step along each axis.
      for (int a = 0; a < 3; ++a) {
        if (!((mask >> a) & 1)) continue;
        std::array<int, 3> q = p;
        q[a] = p[a] - u;
        worst = std::max(worst, v_[At(q[0], q[1], q[2])]);
        q[a] = p[a] + u;
        worst = std::max(worst, v_[At(q[0], q[1], q[2])]);
      }
    }
    const size_t at = At(p[0], p[1], p[2]);
    v_[at] = DiamondEta(v_[at], v_[At(p[0] + d[0], p[1] + d[1], p[2] + d[2])],
                        v_[At(p[0] - d[0], p[1] - d[1], p[2] - d[2])], worst);
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
  int last_;
  const std::atomic<bool>* stop_ = nullptr;
};

bool BuildWithStandIns(PaddedSamples* samples, Hierarchy* h, const HierarchyBuildOptions& options) {
  StandInBuilder builder(samples, h);
  return builder.Run(options);
}

}  // namespace isostream
