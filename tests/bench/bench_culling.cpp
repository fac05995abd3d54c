// Culling trade-off (issue 2): nodes visited with culling by [min f - eta, max f + eta] versus by
// the exact range of f_full over the tetrahedron (the best that stored per-diamond ranges could
// do).
//   build/tests/bench/bench_culling VOLUME EPS ISO...   e.g. bench_culling buckyball:65 0 0.05 0.15
//   0.25
#include <cstdio>
#include <functional>
#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/matrix.hpp>

#include "server/hierarchy/bisection.h"
#include "server/hierarchy/hierarchy.h"
#include "server/volume/load.h"
#include "server/volume/padding.h"
using namespace isostream;
int main(int argc, char** argv) {
  auto volume = LoadVolume(argv[1]);
  auto h = *BuildHierarchy(std::move(*PadToHierarchyDomain(**volume)));
  std::vector<float> iso;
  for (int i = 3; i < argc; ++i) iso.push_back(atof(argv[i]));
  const double eps = atof(argv[2]);
  const auto& tables = ReferenceTets::Get();
  const int k = h->k();
  auto exact = [&](const TetVertices& v, float* lo, float* hi) {
    glm::ivec3 mn = glm::min(glm::min(v[0], v[1]), glm::min(v[2], v[3])),
               mx = glm::max(glm::max(v[0], v[1]), glm::max(v[2], v[3]));
    const glm::dmat3 e(glm::dvec3(v[1] - v[0]), glm::dvec3(v[2] - v[0]), glm::dvec3(v[3] - v[0]));
    const glm::dmat3 inv = glm::inverse(e);
    *lo = 1e30f;
    *hi = -1e30f;
    for (int z = mn.z; z <= mx.z; ++z)
      for (int y = mn.y; y <= mx.y; ++y)
        for (int x = mn.x; x <= mx.x; ++x) {
          glm::dvec3 l = inv * (glm::dvec3(x, y, z) - glm::dvec3(v[0]));
          if (l.x < -1e-9 || l.y < -1e-9 || l.z < -1e-9 || l.x + l.y + l.z > 1 + 1e-9) continue;
          float f = h->sample(x, y, z);
          *lo = std::min(*lo, f);
          *hi = std::max(*hi, f);
        }
  };
  for (int mode = 0; mode < 2; ++mode) {
    long visited = 0, leaves = 0;
    std::function<void(const TetVertices&, TetClass, int)> rec = [&](const TetVertices& v,
                                                                     TetClass c, int level) {
      ++visited;
      float lo, hi;
      float fmin = 1e30f, fmax = -1e30f;
      for (int i = 0; i < 4; ++i) {
        float f = h->sample(v[i].x, v[i].y, v[i].z);
        fmin = std::min(fmin, f);
        fmax = std::max(fmax, f);
      }
      if (level == 3 * k) {
        bool any = false;
        for (float s : iso) any |= fmin < s && s <= fmax;
        leaves += any;
        return;
      }
      glm::ivec3 x = RefinementPoint(v);
      float e = h->eta(x.x, x.y, x.z);
      if (mode == 0) {
        lo = fmin - e;
        hi = fmax + e;
      } else
        exact(v, &lo, &hi);
      bool any = false;
      for (float s : iso) any |= lo <= s && s <= hi;
      if (!any) return;
      if (e < eps) {
        bool cr = false;
        for (float s : iso) cr |= fmin < s && s <= fmax;
        leaves += cr;
        return;
      }
      const ReferenceTet& rt = tables[c];
      for (int ch = 0; ch < 2; ++ch) {
        TetVertices cv;
        ChildVertices(rt, v, ch, &cv);
        rec(cv, rt.child[ch], level + 1);
      }
    };
    for (int i = 0; i < 6; ++i) rec(InitialVertices(tables, i, 1 << k), tables.initial_class(i), 0);
    printf("%s eps=%g culling=%s visited=%ld leaves=%ld visited/leaf=%.2f\n", argv[1], eps,
           mode ? "exact-range" : "eta", visited, leaves, double(visited) / leaves);
  }
}
