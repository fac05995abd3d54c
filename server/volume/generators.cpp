#include "server/volume/generators.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "server/volume/grid_builder.h"
#include "server/volume/load.h"

namespace isostream {
namespace {

constexpr double kPhi = 1.6180339887498948482;

// Quintic smoothstep on [0, 1]: C2, so the fields have continuous gradients and curvature.
double Smooth(double u) {
  u = std::clamp(u, 0.0, 1.0);
  return u * u * u * (u * (u * 6.0 - 15.0) + 10.0);
}

// Sample i of N along an axis of [-1, 1]; written so that both ends are exact.
std::vector<double> AxisCoordinates(int n) {
  std::vector<double> c(n);
  for (int i = 0; i < n; ++i) c[i] = -1.0 + 2.0 * i / (n - 1);
  return c;
}

// Closed forms in the header's words; inline here so the sampling loops can vectorise them.
inline double Cayley(double x, double y, double z) { return 16 * x * y * z + 4 * (x + y + z) - 1; }
inline double Radius(double x, double y, double z) { return std::sqrt(x * x + y * y + z * z); }

inline double Shells(double r) {
  // Start from the outermost plateau and add each step back in going inwards.
  // Most samples lie on a plateau, so only a transition the radius is inside costs a smoothstep.
  double f = kShellPlateauValues[kShellCount - 1];
  for (int t = 0; t < kShellCount - 1; ++t) {
    const double step = kShellPlateauValues[t] - kShellPlateauValues[t + 1];
    const double u = (r - kShellTransitionRadii[t] + kShellTransitionHalfWidth) *
                     (0.5 / kShellTransitionHalfWidth);
    if (u <= 0) {
      f += step;
    } else if (u < 1) {
      f += step * (1 - Smooth(u));
    }
  }
  return f;
}

// --- buckyball ----------------------------------------------------------------------------------

struct BuckyballModel {
  std::array<std::array<double, 3>, kBuckyballAtomCount> atoms;
  double sigma[2];      // narrow, broad (world units)
  double amplitude[2];  // scaled so the field at an atom centre is 1
};

const BuckyballModel& Buckyball() {
  static const BuckyballModel model = [] {
    BuckyballModel m{};
    // Even permutations are the three cyclic rotations of each sign variant.
    const double base[3][3] = {
        {0, 1, 3 * kPhi}, {1, 2 + kPhi, 2 * kPhi}, {kPhi, 2, kPhi * kPhi * kPhi}};
    const double circumradius = std::sqrt(1 + 9 * kPhi * kPhi);  // of the edge-2 solid
    const double scale = kBuckyballCageRadius / circumradius;
    int count = 0;
    for (const auto& b : base) {
      for (int signs = 0; signs < 8; ++signs) {
        // A zero coordinate has one sign only: skip the variants that would flip it.
        bool duplicate = false;
        double v[3];
        for (int c = 0; c < 3; ++c) {
          const bool flip = (signs >> c) & 1;
          if (flip && b[c] == 0) duplicate = true;
          v[c] = flip ? -b[c] : b[c];
        }
        if (duplicate) continue;
        for (int r = 0; r < 3; ++r) {
          m.atoms[count++] = {v[r] * scale, v[(r + 1) % 3] * scale, v[(r + 2) % 3] * scale};
        }
      }
    }
    const double edge = 2 * scale;
    m.sigma[0] = kBuckyballNarrowSigmaPerEdge * edge;
    m.sigma[1] = kBuckyballBroadSigmaPerEdge * edge;
    m.amplitude[0] = 1;
    m.amplitude[1] = kBuckyballBroadToNarrowAmplitude;
    // Normalise: every atom is equivalent under the icosahedral group, so one suffices.
    double peak = 0;
    for (const auto& a : m.atoms) {
      double d2 = 0;
      for (int c = 0; c < 3; ++c) d2 += (a[c] - m.atoms[0][c]) * (a[c] - m.atoms[0][c]);
      for (int g = 0; g < 2; ++g)
        peak += m.amplitude[g] * std::exp(-d2 / (2 * m.sigma[g] * m.sigma[g]));
    }
    m.amplitude[0] /= peak;
    m.amplitude[1] /= peak;
    return m;
  }();
  return model;
}

// Gaussians are separable: exp(-|p-a|^2/2s^2) = gx(x) gy(y) gz(z). Per-axis factor tables turn
// the 120-term sum into one multiply-add per live term per sample along a row, and the window
// [lo, hi) skips the samples where a factor is below kCutoff (contribution < 1e-7 of the peak).
class BuckyballRows {
 public:
  static constexpr int kTerms = 2 * kBuckyballAtomCount;
  static constexpr double kCutoff = 1e-7;

  explicit BuckyballRows(const std::vector<double>& coords) : n_(static_cast<int>(coords.size())) {
    const BuckyballModel& m = Buckyball();
    table_.assign(static_cast<size_t>(kTerms) * 3 * n_, 0.0f);
    for (int t = 0; t < kTerms; ++t) {
      const int g = t / kBuckyballAtomCount;
      const auto& atom = m.atoms[t % kBuckyballAtomCount];
      amplitude_[t] = m.amplitude[g];
      for (int axis = 0; axis < 3; ++axis) {
        float* f = Factors(t, axis);
        int lo = n_, hi = 0;
        for (int i = 0; i < n_; ++i) {
          const double d = coords[i] - atom[axis];
          const double v = std::exp(-d * d / (2 * m.sigma[g] * m.sigma[g]));
          if (v < kCutoff) continue;
          f[i] = static_cast<float>(v);
          lo = std::min(lo, i);
          hi = std::max(hi, i + 1);
        }
        window_[t][axis] = {lo, std::max(lo, hi)};
      }
    }
  }

  void operator()(int j, int k, float* out) const {
    std::fill(out, out + n_, 0.0f);
    for (int t = 0; t < kTerms; ++t) {
      const float w = static_cast<float>(amplitude_[t]) * Factors(t, 1)[j] * Factors(t, 2)[k];
      if (w < kCutoff) continue;
      const float* fx = Factors(t, 0);
      for (int i = window_[t][0][0]; i < window_[t][0][1]; ++i) out[i] += w * fx[i];
    }
  }

 private:
  float* Factors(int t, int axis) { return &table_[(static_cast<size_t>(t) * 3 + axis) * n_]; }
  const float* Factors(int t, int axis) const {
    return &table_[(static_cast<size_t>(t) * 3 + axis) * n_];
  }

  int n_;
  std::vector<float> table_;
  double amplitude_[kTerms];
  std::array<int, 2> window_[kTerms][3];
};

// --- noise --------------------------------------------------------------------------------------

constexpr double kOctaveWeight[kNoiseOctaves] = {4.0 / 7, 2.0 / 7, 1.0 / 7};

uint32_t Mix(uint32_t h) {
  // murmur3's finaliser: every input bit flips about half the output bits.
  h ^= h >> 16;
  h *= 0x85ebca6bu;
  h ^= h >> 13;
  h *= 0xc2b2ae35u;
  h ^= h >> 16;
  return h;
}

double Lattice(int x, int y, int z, int octave, uint32_t seed) {
  uint32_t h = Mix(seed * 0x9e3779b9u + static_cast<uint32_t>(octave));
  h = Mix(h ^ static_cast<uint32_t>(x));
  h = Mix(h ^ static_cast<uint32_t>(y) * 0x27d4eb2du);
  h = Mix(h ^ static_cast<uint32_t>(z) * 0x165667b1u);
  return (h >> 8) * (2.0 / 16777215.0) - 1.0;
}

struct NoiseAxis {
  int cell;
  double weight;  // smoothstep of the position inside the cell
};

NoiseAxis Locate(double coord, int octave) {
  const double u = coord * (1 << octave) / kNoiseBaseCell;
  const double cell = std::floor(u);
  return {static_cast<int>(cell), Smooth(u - cell)};
}

// The y-z blend of one lattice plane x = IX; a row along x reuses it for a whole cell.
double NoiseFace(int ix, const NoiseAxis& ay, const NoiseAxis& az, int octave, uint32_t seed) {
  const double v00 = Lattice(ix, ay.cell, az.cell, octave, seed);
  const double v10 = Lattice(ix, ay.cell + 1, az.cell, octave, seed);
  const double v01 = Lattice(ix, ay.cell, az.cell + 1, octave, seed);
  const double v11 = Lattice(ix, ay.cell + 1, az.cell + 1, octave, seed);
  const double a = v00 + (v10 - v00) * ay.weight;
  const double b = v01 + (v11 - v01) * ay.weight;
  return a + (b - a) * az.weight;
}

class NoiseRows {
 public:
  // Lattice planes crossed by [-1, 1] at the finest octave, plus the closing plane and slack.
  static constexpr int kMaxPlanes =
      static_cast<int>(2 * (1 << (kNoiseOctaves - 1)) / kNoiseBaseCell) + 3;

  // Every axis samples the same coordinates, so one table of cells and weights serves x, y, z.
  NoiseRows(const std::vector<double>& coords, uint32_t seed)
      : n_(static_cast<int>(coords.size())), seed_(seed) {
    for (int o = 0; o < kNoiseOctaves; ++o) {
      axis_[o].resize(n_);
      for (int i = 0; i < n_; ++i) axis_[o][i] = Locate(coords[i], o);
    }
  }

  // Same arithmetic, in the same order, as NoiseValue: rows equal the point function exactly.
  // The y-z blends of the lattice planes the row crosses are computed once per row, so the
  // per-sample work is two table reads and a lerp per octave.
  void operator()(int j, int k, float* out) const {
    double faces[kNoiseOctaves][kMaxPlanes];
    int first_cell[kNoiseOctaves];
    for (int o = 0; o < kNoiseOctaves; ++o) {
      first_cell[o] = axis_[o][0].cell;
      const int planes = axis_[o][n_ - 1].cell + 2 - first_cell[o];
      for (int p = 0; p < planes; ++p) {
        faces[o][p] = NoiseFace(first_cell[o] + p, axis_[o][j], axis_[o][k], o, seed_);
      }
    }
    for (int i = 0; i < n_; ++i) {
      double sum = 0;
      for (int o = 0; o < kNoiseOctaves; ++o) {
        const NoiseAxis& ax = axis_[o][i];
        const double f0 = faces[o][ax.cell - first_cell[o]];
        const double f1 = faces[o][ax.cell - first_cell[o] + 1];
        sum += kOctaveWeight[o] * (f0 + (f1 - f0) * ax.weight);
      }
      out[i] = static_cast<float>(sum);
    }
  }

 private:
  int n_;
  uint32_t seed_;
  std::vector<NoiseAxis> axis_[kNoiseOctaves];
};

// --- sampling -----------------------------------------------------------------------------------

// Fills a slab of rows in parallel, then hands it to the builder; ROW(j, k, out) writes the N
// samples of row (y = j, z = k). One call per row keeps dispatch out of the per-sample loop.
template <typename RowFn>
absl::StatusOr<VolumePtr> SampleRows(std::string_view spec, const char* grid_name, int n,
                                     const std::atomic<bool>* stop, const RowFn& row) {
  DenseGridBuilder builder({n, n, n});
  std::vector<float> slab(builder.SlabSamples(0));
  for (int s = 0; s < builder.slab_count(); ++s) {
    if (stop && stop->load(std::memory_order_relaxed))
      return absl::CancelledError(std::string(spec) + ": generation stopped");
    const int rows = builder.SlabPlanes(s) * n;
    tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& r) {
      for (int q = r.begin(); q != r.end(); ++q) {
        row(q % n, s * kSlabDepth + q / n, slab.data() + static_cast<size_t>(q) * n);
      }
    });
    absl::Status status = builder.AddSlab(s, slab.data());
    if (!status.ok()) {
      return absl::Status(status.code(), std::string(spec) + ": " + std::string(status.message()));
    }
  }
  const double h = 2.0 / (n - 1);
  return builder.Finish(std::string(spec), grid_name, {h, h, h}, {-1.0, -1.0, -1.0});
}

// Samples a point function row by row; fine for the closed forms that cost a few flops.
template <typename PointFn>
absl::StatusOr<VolumePtr> SamplePoints(std::string_view spec, const char* grid_name, int n,
                                       const std::atomic<bool>* stop, PointFn f) {
  const std::vector<double> c = AxisCoordinates(n);
  return SampleRows(spec, grid_name, n, stop, [&](int j, int k, float* out) {
    for (int i = 0; i < n; ++i) out[i] = static_cast<float>(f(c[i], c[j], c[k]));
  });
}

const char* const kGeneratorNames[] = {"cayley", "buckyball", "sphere", "shells", "noise", nullptr};

}  // namespace

const char* const* GeneratorNames() { return kGeneratorNames; }

const std::array<std::array<double, 3>, kBuckyballAtomCount>& BuckyballAtoms() {
  return Buckyball().atoms;
}

double CayleyValue(double x, double y, double z) { return Cayley(x, y, z); }

double SphereValue(double x, double y, double z) { return Radius(x, y, z); }

double ShellsValue(double r) { return Shells(r); }

double BuckyballValue(double x, double y, double z) {
  const BuckyballModel& m = Buckyball();
  double f = 0;
  for (const auto& a : m.atoms) {
    const double d2 = (x - a[0]) * (x - a[0]) + (y - a[1]) * (y - a[1]) + (z - a[2]) * (z - a[2]);
    for (int g = 0; g < 2; ++g) f += m.amplitude[g] * std::exp(-d2 / (2 * m.sigma[g] * m.sigma[g]));
  }
  return f;
}

double NoiseValue(double x, double y, double z, uint32_t seed) {
  double sum = 0;
  for (int o = 0; o < kNoiseOctaves; ++o) {
    const NoiseAxis ax = Locate(x, o), ay = Locate(y, o), az = Locate(z, o);
    const double f0 = NoiseFace(ax.cell, ay, az, o, seed);
    const double f1 = NoiseFace(ax.cell + 1, ay, az, o, seed);
    sum += kOctaveWeight[o] * (f0 + (f1 - f0) * ax.weight);
  }
  return sum;
}

absl::StatusOr<VolumePtr> GenerateVolume(const VolumeSpec& spec, const std::atomic<bool>* stop) {
  const std::string_view name = spec.generator;
  const int size = spec.n;
  if (name == "cayley") {
    return SamplePoints(spec.text, "cayley", size, stop,
                        [](double x, double y, double z) { return Cayley(x, y, z); });
  }
  if (name == "sphere") {
    return SamplePoints(spec.text, "sphere", size, stop,
                        [](double x, double y, double z) { return Radius(x, y, z); });
  }
  if (name == "shells") {
    return SamplePoints(spec.text, "shells", size, stop,
                        [](double x, double y, double z) { return Shells(Radius(x, y, z)); });
  }
  if (name == "buckyball") {
    const BuckyballRows rows(AxisCoordinates(size));
    return SampleRows(spec.text, "buckyball", size, stop, rows);
  }
  if (name == "noise") {
    const std::vector<double> coords = AxisCoordinates(size);
    return SampleRows(spec.text, "noise", size, stop, NoiseRows(coords, spec.seed));
  }
  return absl::NotFoundError("generator spec '" + spec.text + "': unknown generator '" +
                             spec.generator + "'");
}

}  // namespace isostream
