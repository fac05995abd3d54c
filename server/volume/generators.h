// Built-in synthetic volumes. Every generator samples a closed-form field over the cube
// [-1, 1]^3 with N samples per axis (spacing 2 / (N - 1), sample (0, 0, 0) at (-1, -1, -1)), so
// the same field can be sampled at any N and tests can compare grid samples with the formula.
//
//   cayley:N     f = 16xyz + 4(x + y + z) - 1. The level set f = 0 is Cayley's cubic surface
//                (four conical singular points), a classic test of topology handling.
//   sphere:N     f = |p|. The level set f = r is the sphere of radius r.
//   shells:N     f = ShellsValue(|p|): concentric plateaus with exactly known values, see below.
//   buckyball:N  f = sum over the 60 atoms of C60 of a narrow plus a broad Gaussian, see below.
//   noise:N[:S]  f = NoiseValue(p, S): smooth seeded value noise in [-1, 1], default seed 1.
//
// The point functions below are the reference the grids are sampled from; they exist so tests
// (and later isovalue tests) can check samples and plateau values without a copy of the formula.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>

#include "server/volume/volume.h"
#include "server/volume/volume_spec.h"
#include "shared/status.h"

namespace isostream {

// --- shells -------------------------------------------------------------------------------------
// Plateau values from the centre outwards. Between transition t-1 and t the field is exactly
// kShellPlateauValues[t]; plateau 0 is the ball r <= kShellTransitionRadii[0] -
// kShellTransitionHalfWidth, the last plateau (value 0) extends to the cube's corners.
// Each transition is a quintic smoothstep (C2, compact support) of width
// 2 * kShellTransitionHalfWidth centred at kShellTransitionRadii[t], so the plateaus are exact
// (a tanh would never reach them) and an isovalue strictly between two plateau values gives one
// sphere of radius in (r_t - w, r_t + w).
//
//   r in [0, 0.15]      1.00
//   r in [0.25, 0.35]   0.75
//   r in [0.45, 0.55]   0.50
//   r in [0.65, 0.75]   0.25
//   r >= 0.85           0.00
inline constexpr int kShellCount = 5;
inline constexpr std::array<float, kShellCount> kShellPlateauValues = {1.0f, 0.75f, 0.5f, 0.25f,
                                                                       0.0f};
inline constexpr std::array<double, kShellCount - 1> kShellTransitionRadii = {0.2, 0.4, 0.6, 0.8};
inline constexpr double kShellTransitionHalfWidth = 0.05;

// --- buckyball ----------------------------------------------------------------------------------
// Atoms: the 60 vertices of the truncated icosahedron (edge length 2 before scaling), the even
// permutations of (0, ±1, ±3φ), (±1, ±(2+φ), ±2φ), (±φ, ±2, ±φ^3), scaled so that the atoms lie
// on a sphere of radius kBuckyballCageRadius.
//
// Each atom carries A1 exp(-d^2 / 2σ1^2) + A2 exp(-d^2 / 2σ2^2). In units of the edge length e:
// σ1 = 0.21 e, σ2 = 0.70 e, A2 / A1 = 0.045, and A1, A2 are scaled so the field at an atom centre
// is exactly 1. A single Gaussian width cannot give three different topologies: a width that
// closes the hexagonal faces at 0.05 also fuses the atoms at 0.25. With the narrow + broad pair
// (values found by a parameter scan for the largest margin to every threshold):
//   bond midpoint (saddle between bonded atoms)         0.204  -> atoms apart at 0.25, bonded at
//   0.15 max along the ray through a hexagon / pentagon centre  0.095 / 0.108 -> faces closed at
//   0.05,
//                                                                           open at 0.15
//   cage centre                                          0.005  -> hollow inside at 0.05
//   field beyond radius 0.95                             < 0.001 -> every surface closed in the
//   cube
// So isovalue 0.05 gives a closed hollow shell enclosing the cage (outer and inner sheet), 0.15
// the bond network (a genus-31 cage), 0.25 sixty separate atom spheres — nested and distinct,
// like Gerstner and Pajarola's Fig. 5.
inline constexpr int kBuckyballAtomCount = 60;
inline constexpr double kBuckyballCageRadius = 0.52;
inline constexpr double kBuckyballNarrowSigmaPerEdge = 0.21;
inline constexpr double kBuckyballBroadSigmaPerEdge = 0.70;
inline constexpr double kBuckyballBroadToNarrowAmplitude = 0.045;

// Atom centres in world coordinates, computed from the golden ratio.
const std::array<std::array<double, 3>, kBuckyballAtomCount>& BuckyballAtoms();

// --- noise --------------------------------------------------------------------------------------
// Three octaves of value noise: lattice values hashed from (cell, octave, seed) into [-1, 1],
// blended with the quintic smoothstep (C2) and summed with weights 4/7, 2/7, 1/7, so every value
// is a convex combination of lattice values and lies in [-1, 1]. The coarsest lattice has
// kNoiseBaseCell world units per cell (4 cells across the cube), each octave halves it.
inline constexpr int kNoiseOctaves = 3;
inline constexpr double kNoiseBaseCell = 0.5;
inline constexpr uint32_t kNoiseDefaultSeed = 1;

// --- point functions (the reference the grids are sampled from) ---------------------------------
double CayleyValue(double x, double y, double z);
double SphereValue(double x, double y, double z);
double ShellsValue(double r);
double BuckyballValue(double x, double y, double z);
double NoiseValue(double x, double y, double z, uint32_t seed);

// Samples the generator a parsed spec names (ParseVolumeSpec has checked its name, N and seed
// against the limits); the volume is named by the spec's text. `stop`, if set and true, ends
// the sampling between slabs with CANCELLED (a 1025^3 volume takes seconds).
absl::StatusOr<VolumePtr> GenerateVolume(const VolumeSpec& spec,
                                         const std::atomic<bool>* stop = nullptr);

}  // namespace isostream
