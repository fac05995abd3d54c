// Small synthetic volumes for unit tests, built straight into hierarchy samples.
#pragma once

#include <cmath>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "server/extract/extract_request.h"
#include "server/hierarchy/hierarchy.h"

namespace isostream::testing {

// Samples f over [-1,1]^3 on a (2^k+1)^3 cube; data_dims may shrink the data box.
inline PaddedSamples MakeSamples(int k, const std::function<float(double, double, double)>& f) {
  PaddedSamples s;
  s.k = k;
  s.n = (1 << k) + 1;
  s.data_dims = {s.n, s.n, s.n};
  s.values.resize(static_cast<size_t>(s.n) * s.n * s.n);
  const double c = 2.0 / (s.n - 1);
  for (int z = 0; z < s.n; ++z)
    for (int y = 0; y < s.n; ++y)
      for (int x = 0; x < s.n; ++x)
        s.values[(static_cast<size_t>(z) * s.n + y) * s.n + x] = f(x * c - 1, y * c - 1, z * c - 1);
  return s;
}

inline HierarchyPtr MakeHierarchy(int k, const std::function<float(double, double, double)>& f) {
  auto h = BuildHierarchy(MakeSamples(k, f));
  return h.ok() ? *h : nullptr;
}

// A request for these isovalues seen from (40, -13, 57), outside the test volumes: what the
// count and budget tests ask of a hierarchy.
inline ExtractRequest CountingRequest(std::vector<float> iso) {
  ExtractRequest r;
  r.isovalues = std::move(iso);
  r.view.eye = {40, -13, 57};
  return r;
}

inline float SphereField(double x, double y, double z) {
  return float(std::sqrt(x * x + y * y + z * z));
}
// Three Gaussian blobs: nested, closed level sets well inside the domain.
inline float BlobsField(double x, double y, double z) {
  auto g = [&](double cx, double cy, double cz, double s) {
    const double d2 = (x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz);
    return std::exp(-d2 / (s * s));
  };
  return float(g(-0.3, -0.2, 0.1, 0.35) + g(0.35, 0.25, -0.1, 0.3) + 0.8 * g(0.0, 0.3, 0.35, 0.25));
}
// Nested terraces, flat between steps at multiples of 0.25: an isovalue on a terrace (0.5)
// meets corners at exactly the isovalue, where central differences vanish.
inline float TerracesField(double x, double y, double z) {
  return float(std::floor(4 * std::sqrt(x * x + y * y + z * z)) / 4);
}
inline float CayleyField(double x, double y, double z) {
  return float(16 * x * y * z + 4 * (x + y + z) - 1);
}

// A volume and the isovalues a test extracts from it.
struct VolumeCase {
  HierarchyPtr h;
  std::vector<float> iso;
  std::string name;
};

// Cayley's surface in a 13 x 17 x 11 data box inside a 17^3 cube: leaves straddling the box are
// clipped (and blocks fall back to node by node there).
inline VolumeCase ClippedCayley() {
  PaddedSamples s = MakeSamples(4, CayleyField);
  s.data_dims = {13, 17, 11};
  auto clipped = BuildHierarchy(std::move(s));
  return {clipped.ok() ? *clipped : nullptr, {-0.3f, 0.05f, 0.4f}, "cayley clipped"};
}

}  // namespace isostream::testing
