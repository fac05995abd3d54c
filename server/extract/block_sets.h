// Bit-set arithmetic of a three-level block (traversal.h): which of its 10 points lie on the
// upper side of an isovalue, and which of its 8 finest tetrahedra have corners on both sides;
// and the same side test for one tetrahedron's 4 corners.
// SSE2 where available; the scalar forms define the result and are tested against it.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "server/hierarchy/block_tables.h"

#ifdef __SSE2__
#include <emmintrin.h>
#endif

namespace isostream::extract_internal {

// Bit i: f[i] >= iso (false for NaN), for the block's 10 points.
inline unsigned AbovePointsScalar(const float* f, float iso) {
  unsigned m = 0;
  for (int i = 0; i < kBlockPoints; ++i) m |= unsigned(f[i] >= iso) << i;
  return m;
}

// Bit j: the finest tetrahedron j, with corner set leaf_corners[j], has corners on both sides.
inline unsigned CrossingLeavesScalar(const uint16_t* leaf_corners, unsigned above) {
  unsigned crossing = 0;
  for (int j = 0; j < kBlockNodes / 2; ++j) {
    const unsigned x = above & leaf_corners[j];
    crossing |= unsigned(x != 0 && x != leaf_corners[j]) << j;
  }
  return crossing;
}

inline unsigned AbovePoints(const float* f, float iso) {
#ifdef __SSE2__
  const __m128 v = _mm_set1_ps(iso);
  const unsigned lo = unsigned(_mm_movemask_ps(_mm_cmpge_ps(_mm_loadu_ps(f), v)));
  const unsigned mid = unsigned(_mm_movemask_ps(_mm_cmpge_ps(_mm_loadu_ps(f + 4), v)));
  return lo | mid << 4 | unsigned(f[8] >= iso) << 8 | unsigned(f[9] >= iso) << 9;
#else
  return AbovePointsScalar(f, iso);
#endif
}

// Bit i: f[i] >= iso (false for NaN), for a tetrahedron's 4 corners: its marching-tetrahedra
// case (leaf_emitter.h).
inline unsigned AboveCornersScalar(const float* f, float iso) {
  unsigned m = 0;
  for (int i = 0; i < 4; ++i) m |= unsigned(f[i] >= iso) << i;
  return m;
}

inline unsigned AboveCorners(const float* f, float iso) {
#ifdef __SSE2__
  return unsigned(_mm_movemask_ps(_mm_cmpge_ps(_mm_loadu_ps(f), _mm_set1_ps(iso))));
#else
  return AboveCornersScalar(f, iso);
#endif
}

// Corners whose value equals iso: their crossings are the corner's vertex (LeafEmitter).
inline unsigned CornersAtIso(const float* f, float iso) {
#ifdef __SSE2__
  return unsigned(_mm_movemask_ps(_mm_cmpeq_ps(_mm_loadu_ps(f), _mm_set1_ps(iso))));
#else
  unsigned m = 0;
  for (int i = 0; i < 4; ++i) m |= unsigned(f[i] == iso) << i;
  return m;
#endif
}

// Corners whose value is within tau times the largest distance of a corner's value from iso,
// doubled: a superset of those a crossing can round onto, on some coordinate (Context::snap_tau
// bounds the parameter of a crossing with a stored coordinate of one of its edge's ends, and a
// crossed edge's values differ by at most that doubled distance). A superset is harmless (such
// components take the exact path); a missed corner would not be.
inline unsigned CornersNearIsoScalar(const float* f, float iso, float tau) {
  float dist[4], farthest = 0;
  for (int i = 0; i < 4; ++i) farthest = std::max(farthest, dist[i] = std::abs(f[i] - iso));
  const float band = 2 * farthest * tau;
  unsigned m = 0;
  for (int i = 0; i < 4; ++i) m |= unsigned(dist[i] <= band) << i;
  return m;
}

inline unsigned CornersNearIso(const float* f, float iso, float tau) {
#ifdef __SSE2__
  const __m128 dist =
      _mm_andnot_ps(_mm_set1_ps(-0.0f), _mm_sub_ps(_mm_loadu_ps(f), _mm_set1_ps(iso)));
  __m128 far = _mm_max_ps(dist, _mm_shuffle_ps(dist, dist, _MM_SHUFFLE(2, 3, 0, 1)));
  far = _mm_max_ps(far, _mm_shuffle_ps(far, far, _MM_SHUFFLE(1, 0, 3, 2)));
  const __m128 band = _mm_mul_ps(_mm_add_ps(far, far), _mm_set1_ps(tau));
  return unsigned(_mm_movemask_ps(_mm_cmple_ps(dist, band)));
#else
  return CornersNearIsoScalar(f, iso, tau);
#endif
}

// leaf_corners: 16-byte aligned (BlockTables::leaf_corners).
inline unsigned CrossingLeaves(const uint16_t* leaf_corners, unsigned above) {
#ifdef __SSE2__
  static_assert(kBlockNodes / 2 == 8, "8 finest tetrahedra: one 16-bit lane each");
  const __m128i corners = _mm_load_si128(reinterpret_cast<const __m128i*>(leaf_corners));
  const __m128i x = _mm_and_si128(corners, _mm_set1_epi16(short(above)));
  const __m128i one_side =
      _mm_or_si128(_mm_cmpeq_epi16(x, _mm_setzero_si128()), _mm_cmpeq_epi16(x, corners));
  return ~unsigned(_mm_movemask_epi8(_mm_packs_epi16(one_side, one_side))) & 0xffu;
#else
  return CrossingLeavesScalar(leaf_corners, above);
#endif
}

}  // namespace isostream::extract_internal
