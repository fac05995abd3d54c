#include "server/extract/view_context.h"

#include <algorithm>
#include <cmath>
#include <glm/geometric.hpp>
#include <limits>

namespace isostream::extract_internal {

void SetView(Context* c, const GridToWorld& xf, const View& view, DrawOrder order) {
  c->ordered = order == DrawOrder::kBackToFront;
  c->orthographic = view.orthographic;
  // Affine maps keep planes and sides: order in grid space with the eye mapped there.
  c->eye = (view.eye - xf.origin) / xf.spacing;
  glm::dvec3 d = view.direction;
  const double eye_far = std::max({std::abs(c->eye.x), std::abs(c->eye.y), std::abs(c->eye.z)});
  if (!c->orthographic && !(eye_far <= 0x1p52)) {
    // So far that grid points' offsets from the eye are lost (or its grid coordinates
    // overflow, and the plane sides would turn NaN): the volume is seen as from infinity,
    // which is the orthographic view along the direction from the eye to it.
    c->orthographic = true;
    d = xf.origin + xf.spacing * (0.5 * double(1 << c->k)) - view.eye;
  }
  // Only the direction's sense matters: scaled to a largest component of 1 first, so a huge
  // finite one (1e307) cannot overflow to inf, and 0 * inf to NaN, on the way to grid space.
  const double d_max = std::max({std::abs(d.x), std::abs(d.y), std::abs(d.z)});
  c->dir = d_max > 0 ? (d / d_max) / xf.spacing : d;

  const ReferenceTets& tables = ReferenceTets::Get();
  for (int i = 0; i < kNumTetClasses; ++i) {
    const auto& ni = tables[TetClass{uint8_t(i)}].plane_normal_int;
    const glm::dvec3 n(ni[0], ni[1], ni[2]);
    unsigned plus = 0, minus = 0;
    for (int a = 0; a < 3; ++a) {
      if (ni[a] == 1) plus |= 1u << a;
      if (ni[a] == -1) minus |= 1u << a;
    }
    c->plane_plus[i] = FieldSumMultiplier(plus);
    c->plane_minus[i] = FieldSumMultiplier(minus);
    // normal . x >= normal . eye, for an integer left side: >= its ceiling. Past +-2^40 (far
    // beyond any grid's |normal . x| < 2^15) the answer is the same for every x: never or
    // always. Not a number (an eye whose grid coordinates overflow): never.
    const double eye_side = glm::dot(n, c->eye);
    constexpr double kFar = 1099511627776.0;  // 2^40
    c->plane_at_least[i] = !(eye_side <= kFar) ? std::numeric_limits<int64_t>::max()
                           : eye_side < -kFar  ? std::numeric_limits<int64_t>::min()
                                               : int64_t(std::ceil(eye_side));
    c->ortho_child0_first[i] = glm::dot(n, c->dir) >= 0;  // eye on child 1's side of every plane
  }
}

}  // namespace isostream::extract_internal
