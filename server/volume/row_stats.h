// Min, max and "not finite" over rows of 8 floats, lane by lane, reduced at the end: the
// statistics DenseGridBuilder takes of every sample while it transposes rows into leaves.
// Private to server/volume.
//
// Two forms with one result: SSE2 (the compare-select minimum equals the scalar one, NaN
// included) and a portable scalar one for targets without it, which gcc does not vectorise
// (2x the instructions of the SSE2 form at cayley:257). Both are compiled on x86 so the test
// can hold them equal.
#pragma once

#include <algorithm>
#include <cfloat>
#include <cmath>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

namespace isostream::volume_internal {

struct RowStatsScalar {
  float lo[8], hi[8];
  bool bad;
  void Reset(float l, float h) {
    for (int i = 0; i < 8; ++i) lo[i] = l, hi[i] = h;
    bad = false;
  }
  void Add(const float* row) {
    for (int i = 0; i < 8; ++i) {
      lo[i] = row[i] < lo[i] ? row[i] : lo[i];
      hi[i] = row[i] > hi[i] ? row[i] : hi[i];
      bad |= !(std::fabs(row[i]) <= FLT_MAX);
    }
  }
  void Finish(float* l, float* h, bool* any_bad) const {
    for (int i = 0; i < 8; ++i) *l = std::min(*l, lo[i]), *h = std::max(*h, hi[i]);
    *any_bad |= bad;
  }
};

#ifdef __SSE2__
struct RowStatsSse2 {
  __m128 lo[2], hi[2], bad;
  void Reset(float l, float h) {
    lo[0] = lo[1] = _mm_set1_ps(l);
    hi[0] = hi[1] = _mm_set1_ps(h);
    bad = _mm_setzero_ps();
  }
  void Add(const float* row) {
    const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
    const __m128 largest = _mm_set1_ps(FLT_MAX);
    for (int half = 0; half < 2; ++half) {
      const __m128 v = _mm_loadu_ps(row + 4 * half);
      lo[half] = _mm_min_ps(v, lo[half]);                                     // v < lo ? v : lo
      hi[half] = _mm_max_ps(v, hi[half]);                                     // v > hi ? v : hi
      bad = _mm_or_ps(bad, _mm_cmpnle_ps(_mm_and_ps(v, abs_mask), largest));  // NaN too
    }
  }
  void Finish(float* l, float* h, bool* any_bad) const {
    float lanes_lo[8], lanes_hi[8];
    _mm_storeu_ps(lanes_lo, lo[0]), _mm_storeu_ps(lanes_lo + 4, lo[1]);
    _mm_storeu_ps(lanes_hi, hi[0]), _mm_storeu_ps(lanes_hi + 4, hi[1]);
    for (int i = 0; i < 8; ++i) *l = std::min(*l, lanes_lo[i]), *h = std::max(*h, lanes_hi[i]);
    *any_bad |= _mm_movemask_ps(bad) != 0;
  }
};
using RowStats = RowStatsSse2;
#else
using RowStats = RowStatsScalar;
#endif

}  // namespace isostream::volume_internal
