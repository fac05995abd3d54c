// QuantizationFor: the box and bit count of a volume's compressed positions (the daemon's
// frames, the CLI's .glb), for every placement the loaders accept (each spacing in
// [1e-30, 1e30] world units): within 1/64 of the smallest spacing of the exact positions, plus
// the float arithmetic's few steps of the box's size and distance from the origin
// (PositionErrorBound). An absolute margin around the box once made every
// vertex of a volume with spacing 1e-25 decode to one point, and 24 bits at most could not step
// a volume with spacings 1e20 and 1e-20 (found by adversarial testing).
#include "server/volume/quantization.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <random>
#include <string>

#include "shared/frame_codec.h"
#include "shared/ordered_mesh.h"

namespace isostream {
namespace {

struct Placement {
  const char* what;
  std::array<int, 3> dims;
  std::array<double, 3> spacing;
  std::array<double, 3> origin;
};

const Placement kPlacements[] = {
    {"unit spacing", {129, 129, 129}, {1, 1, 1}, {0, 0, 0}},
    {"a generator's [-1, 1] box", {513, 513, 513}, {2.0 / 512, 2.0 / 512, 2.0 / 512}, {-1, -1, -1}},
    {"CT in millimetres", {512, 512, 300}, {0.48828125, 0.48828125, 1.25}, {-125, -140, -380}},
    {"spacing 1e-25 near 5e-21", {20, 24, 28}, {1e-25, 1e-25, 1e-25}, {5e-21, 0, 0}},
    {"spacing 1e-12", {20, 24, 28}, {1e-12, 1e-12, 1e-12}, {0, 0, 0}},
    // Draco's quantization keeps a box 1e-6 wide and loses one 1e-7 wide.
    {"spacing 1e-6, a box ~3e-5 wide", {20, 24, 28}, {1e-6, 1e-6, 1e-6}, {1, 2, 3}},
    {"spacing 1e-7, a box ~3e-6 wide", {20, 24, 28}, {1e-7, 1e-7, 1e-7}, {0, 0, 0}},
    {"spacing 1e20", {20, 24, 28}, {1e20, 1e20, 1e20}, {-3e21, 0, 1e21}},
    {"spacings 1e20, 1e-20, 1", {20, 24, 28}, {1e20, 1e-20, 1}, {0, 0, 0}},
    {"spacings 10 and 0.001 over 4096 samples", {4096, 2, 2}, {10, 0.001, 0.001}, {0, 0, 0}},
    {"map coordinates", {257, 257, 65}, {10, 10, 2}, {512000, 4100000, -300}},
    {"a box far from the origin", {129, 129, 129}, {1, 1, 1}, {-20000, 3, 5}},
    // 30 bits, the most: 4096 samples 8 apart on one axis, 0.001 on the others.
    {"spacings 8 and 0.001 over 4096 samples", {4096, 2, 2}, {8, 0.001, 0.001}, {0, 0, 0}},
};

Volume VolumeAt(const Placement& p) {
  Volume v;
  v.dims = p.dims;
  v.spacing = p.spacing;
  v.origin = p.origin;
  return v;
}

// The documented counts: the usual volumes keep their compact frames.
TEST(Quantization, BitsForUnitSpacing) {
  for (const auto& [n, bits] : {std::pair{129, 13}, std::pair{513, 15}}) {
    Volume v;
    v.dims = {n, n, n};
    QuantizationBox box;
    int got = -1;
    QuantizationFor(v, &box, &got);
    EXPECT_EQ(got, bits) << n;
  }
}

// Volumes of every size the daemon serves, anisotropic and off the origin: at most 1/64 voxel,
// and a box holding the data.
TEST(Quantization, AtMostOneSixtyFourthVoxel) {
  for (int n : {9, 65, 129, 513, 2049}) {
    Volume v;
    v.dims = {n, n / 2 + 1, n};
    v.spacing = {0.5, 0.25, 0.5};
    v.origin = {-3, 10, 0};
    QuantizationBox box;
    int bits;
    QuantizationFor(v, &box, &bits);
    EXPECT_LE(PositionErrorBound(box, bits), 0.25 / 64 * 1.01) << n;
    for (int a = 0; a < 3; ++a) {
      EXPECT_LT(box.origin[a], v.origin[a]);
      EXPECT_GT(box.origin[a] + box.range, v.origin[a] + v.spacing[a] * (v.dims[a] - 1));
    }
  }
}

// Up to 30 bits before positions go unquantized (24 was the most: past it the bound failed).
TEST(Quantization, BoxesOfUpTo2To25SpacingsAreQuantized) {
  Volume v;
  v.dims = {4096, 2, 2};
  v.spacing = {8, 0.001, 0.001};  // the box spans ~3.3e7 smallest spacings
  QuantizationBox box;
  int bits = -1;
  QuantizationFor(v, &box, &bits);
  EXPECT_EQ(bits, 30);
  v.spacing[0] = 9;  // ~3.7e7: past what 30 bits can step at 1/64 voxel
  QuantizationFor(v, &box, &bits);
  EXPECT_EQ(bits, 0);
}

// Positions anywhere in the data box (its corners included) survive the frame codec within
// 1/64 of the smallest spacing plus four float steps of the box's farthest corner from the
// origin, and within the bound
// the daemon reports (PositionErrorBound); 0 bits (unquantized) only where 30 could not do or
// the box is too narrow for Draco's quantization.
TEST(Quantization, EveryPlacementKeepsItsPositionsWithinTheBound) {
  std::mt19937 rng(7);
  for (const Placement& p : kPlacements) {
    SCOPED_TRACE(p.what);
    QuantizationBox box;
    int bits = -1;
    QuantizationFor(VolumeAt(p), &box, &bits);
    const double voxel = *std::min_element(p.spacing.begin(), p.spacing.end());
    if (bits == 0) {
      EXPECT_TRUE(box.range < kNarrowestQuantizedBox ||
                  box.range / (2 * (std::ldexp(1.0, 30) - 1)) > voxel / 64)
          << "30 bits would do";
    } else {
      EXPECT_GE(bits, 8);
      EXPECT_LE(bits, 30);
      EXPECT_LE(box.range / (2 * (std::ldexp(1.0, bits) - 1)), voxel / 64);
    }
    // A mesh whose vertices are the data box's 8 corners and 4,000 points inside it.
    OrderedMesh mesh;
    auto add = [&](const std::array<double, 3>& at) {
      for (int a = 0; a < 3; ++a) mesh.positions.push_back(float(at[a]));
      for (float n : {0.0f, 0.0f, 1.0f}) mesh.normals.push_back(n);
    };
    for (int corner = 0; corner < 8; ++corner) {
      std::array<double, 3> at;
      for (int a = 0; a < 3; ++a)
        at[a] = p.origin[a] + ((corner >> a) & 1) * p.spacing[a] * (p.dims[a] - 1);
      add(at);
    }
    std::uniform_real_distribution<double> u(0.0, 1.0);
    while (mesh.vertex_count() < 4008) {
      std::array<double, 3> at;
      for (int a = 0; a < 3; ++a) at[a] = p.origin[a] + u(rng) * p.spacing[a] * (p.dims[a] - 1);
      add(at);
    }
    for (uint32_t t = 0; t + 2 < mesh.vertex_count(); t += 3) {
      mesh.triangles.insert(mesh.triangles.end(), {t, t + 1, t + 2});
      mesh.surface.push_back(0);
    }
    for (const auto connectivity :
         {CodecOptions::Connectivity::kEdgeCache, CodecOptions::Connectivity::kDracoSequential}) {
      CodecOptions options;
      options.connectivity = connectivity;
      options.position_bits = bits;
      options.position_box = box;
      std::string bytes;
      ASSERT_TRUE(EncodeChunk(mesh, 0, mesh.triangle_count(), options, &bytes).ok());
      OrderedMesh decoded;
      ASSERT_TRUE(DecodeChunk(bytes.data(), bytes.size(), &decoded).ok());
      ASSERT_EQ(decoded.triangles.size(), mesh.triangles.size());
      const double reported = PositionErrorBound(box, bits);
      const double float_steps =
          bits == 0 ? 0.0
                    : 4 * FLT_EPSILON *
                          (std::max({std::abs(box.origin[0]), std::abs(box.origin[1]),
                                     std::abs(box.origin[2])}) +
                           box.range);
      for (size_t i = 0; i < mesh.triangles.size(); ++i) {
        for (int a = 0; a < 3; ++a) {
          const double exact = mesh.positions[3 * mesh.triangles[i] + a];
          const double got = decoded.positions[3 * decoded.triangles[i] + a];
          ASSERT_LE(std::abs(got - exact), voxel / 64 + float_steps)
              << "vertex " << mesh.triangles[i] << " axis " << a << ", " << bits << " bits";
          ASSERT_LE(std::abs(got - exact), reported) << "the reported bound, " << bits << " bits";
        }
      }
    }
  }
}

}  // namespace
}  // namespace isostream
