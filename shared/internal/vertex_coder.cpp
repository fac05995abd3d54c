#include "shared/internal/vertex_coder.h"

#include <absl/strings/str_cat.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "shared/internal/draco_mesh.h"
#include "shared/internal/symbol_stream.h"
#include "shared/uninitialized_vector.h"

namespace isostream::internal {
namespace {

uint32_t ZigZag(int32_t v) {
  return (static_cast<uint32_t>(v) << 1) ^ static_cast<uint32_t>(v >> 31);
}
int32_t UnZigZag(uint32_t s) { return static_cast<int32_t>(s >> 1) ^ -static_cast<int32_t>(s & 1); }

// A difference taken modulo `modulus`, as the signed value nearest zero: both sides wrap, so
// every decoded value lands back in [0, modulus) and a jump across the range costs as little as
// the short way round.
int32_t WrappedDelta(int64_t value, int64_t previous, int64_t modulus) {
  int64_t d = value - previous;
  if (d > (modulus - 1) / 2) d -= modulus;
  if (d < -(modulus / 2)) d += modulus;
  return static_cast<int32_t>(d);
}

uint32_t Unwrap(uint32_t previous, int32_t delta, uint32_t modulus) {
  int64_t v = int64_t{previous} + delta;
  if (v < 0) v += modulus;
  if (v >= int64_t{modulus}) v -= modulus;
  return static_cast<uint32_t>(v);
}

// The largest zigzagged WrappedDelta for a modulus (-m/2 for even m, (m-1)/2 for odd m):
// decoders reject symbols above it.
uint32_t MaxSymbol(uint32_t modulus) { return modulus - 1; }

float SignNotZero(float v) { return v < 0.0f ? -1.0f : 1.0f; }

// Unit (or zero-free) normal -> octahedral grid coordinates in [0, 2c].
void OctahedralEncode(const float* n, float c, uint32_t* s, uint32_t* t) {
  const float inverse_l1 = 1.0f / (std::fabs(n[0]) + std::fabs(n[1]) + std::fabs(n[2]));
  float u = n[0] * inverse_l1, v = n[1] * inverse_l1;
  if (n[2] < 0.0f) {
    const float fu = (1.0f - std::fabs(v)) * SignNotZero(u);
    const float fv = (1.0f - std::fabs(u)) * SignNotZero(v);
    u = fu;
    v = fv;
  }
  // Round to nearest: c (1 + u) + 0.5 is positive, so truncation is floor (no libm call).
  *s = std::min(static_cast<uint32_t>((u + 1.0f) * c + 0.5f), 2 * static_cast<uint32_t>(c));
  *t = std::min(static_cast<uint32_t>((v + 1.0f) * c + 0.5f), 2 * static_cast<uint32_t>(c));
}

void OctahedralDecode(uint32_t s, uint32_t t, float c, float* n) {
  float u = (static_cast<float>(s) - c) / c, v = (static_cast<float>(t) - c) / c;
  const float z = 1.0f - std::fabs(u) - std::fabs(v);
  if (z < 0.0f) {
    const float fu = (1.0f - std::fabs(v)) * SignNotZero(u);
    const float fv = (1.0f - std::fabs(u)) * SignNotZero(v);
    u = fu;
    v = fv;
  }
  const float inverse_length = 1.0f / std::sqrt(u * u + v * v + z * z);
  n[0] = u * inverse_length;
  n[1] = v * inverse_length;
  n[2] = z * inverse_length;
}

bool IsZero(const float* v) { return v[0] == 0.0f && v[1] == 0.0f && v[2] == 0.0f; }

template <typename T>
void Put(std::string* out, T value) {
  out->append(reinterpret_cast<const char*>(&value), sizeof(T));
}

}  // namespace

absl::Status EncodeChunkVertices(const GatheredChunk& chunk, int position_bits, int normal_bits,
                                 const QuantizationBox* box, std::string* out) {
  const size_t vertex_count = chunk.vertex_count();
  const bool has_normals = !chunk.normals.empty();
  if (!has_normals) normal_bits = 0;
  // Scratch written before it is read: no zeroing.
  UninitializedVector<uint32_t> symbols(3 * vertex_count);
  UninitializedVector<uint8_t> tags(vertex_count);
  size_t defined_normals = 0;
  for (size_t v = 0; v < vertex_count; ++v) {
    const bool undefined = has_normals && IsZero(&chunk.normals[3 * v]);
    tags[v] = chunk.vertex_surface[v] | (undefined ? kUndefinedNormalBit : 0);
    defined_normals += has_normals && !undefined;
  }

  Put<uint8_t>(out, static_cast<uint8_t>(position_bits));
  Put<uint8_t>(out, static_cast<uint8_t>(normal_bits));
  QuantizationBox own_box;
  const bool check_box = box != nullptr;
  if (position_bits > 0) {
    if (box == nullptr) {
      own_box = BoundingCube(chunk.positions.data(), vertex_count);
      box = &own_box;
    }
    for (int k = 0; k < 3; ++k) Put<float>(out, box->origin[k]);
    Put<float>(out, box->range);
  }

  // Tags in runs: neighbouring vertices nearly always share a surface, so a run costs two
  // symbols where a symbol per vertex would cost rANS work for almost no information.
  uint32_t* run_lengths = symbols.data();
  uint32_t* run_tags = symbols.data() + vertex_count;  // runs <= vertex_count
  uint32_t runs = 0;
  uint8_t previous_tag = 0;
  for (size_t v = 0; v < vertex_count;) {
    size_t end = v + 1;
    while (end < vertex_count && tags[end] == tags[v]) ++end;
    run_lengths[runs] = static_cast<uint32_t>(end - v - 1);
    run_tags[runs] = ZigZag(static_cast<int8_t>(static_cast<uint8_t>(tags[v] - previous_tag)));
    previous_tag = tags[v];
    ++runs;
    v = end;
  }
  Put<uint32_t>(out, runs);
  AppendSymbols(run_lengths, runs, out);
  AppendSymbols(run_tags, runs, out);

  if (position_bits > 0) {
    const uint32_t max_q = (uint32_t{1} << position_bits) - 1;
    const float scale = static_cast<float>(max_q) / box->range;  // as Draco's Quantizer
    const int64_t modulus = int64_t{1} << position_bits;
    uint32_t previous[3] = {0, 0, 0};
    for (size_t v = 0; v < vertex_count; ++v) {
      for (int k = 0; k < 3; ++k) {
        // Draco's floor(offset + 0.5); the offset is >= 0 inside the box, where truncation is
        // floor and costs no libm call. The clamps only guard float rounding at the edges.
        const float inside = chunk.positions[3 * v + k] - box->origin[k];
        if (check_box && !(inside >= 0.0f && inside <= box->range)) {
          // CheckInsideBox's test and message, done here to save a pass over the positions.
          return absl::InvalidArgumentError(
              absl::StrCat("chunk vertex ", v, " coordinate ", k, " = ", chunk.positions[3 * v + k],
                           " lies outside position_box [", box->origin[k], ", ",
                           box->origin[k] + box->range, "]"));
        }
        const float offset = inside * scale + 0.5f;
        const uint32_t q = !(offset > 0.0f)                      ? 0
                           : offset >= static_cast<float>(max_q) ? max_q
                                                                 : static_cast<uint32_t>(offset);
        symbols[3 * v + k] = ZigZag(WrappedDelta(q, previous[k], modulus));
        previous[k] = q;
      }
    }
    AppendSymbols(symbols.data(), 3 * vertex_count, out);
  } else {
    out->append(reinterpret_cast<const char*>(chunk.positions.data()), 12 * vertex_count);
  }

  if (defined_normals > 0) {
    if (normal_bits > 0) {
      const uint32_t center = (uint32_t{1} << (normal_bits - 1)) - 1;
      const float c = static_cast<float>(center);
      const int64_t modulus = 2 * int64_t{center} + 1;
      uint32_t previous[2] = {center, center};
      size_t n = 0;
      for (size_t v = 0; v < vertex_count; ++v) {
        if (tags[v] & kUndefinedNormalBit) continue;
        uint32_t st[2];
        OctahedralEncode(&chunk.normals[3 * v], c, &st[0], &st[1]);
        for (int k = 0; k < 2; ++k) {
          symbols[n++] = ZigZag(WrappedDelta(st[k], previous[k], modulus));
          previous[k] = st[k];
        }
      }
      AppendSymbols(symbols.data(), n, out);
    } else {
      for (size_t v = 0; v < vertex_count; ++v) {
        if (tags[v] & kUndefinedNormalBit) continue;
        out->append(reinterpret_cast<const char*>(&chunk.normals[3 * v]), 12);
      }
    }
  }
  return absl::OkStatus();
}

absl::Status DecodeChunkVertices(const char* data, size_t size, uint32_t vertex_count,
                                 bool has_normals, DecodedChunk* out) {
  if (vertex_count == 0) return absl::DataLossError("vertex part: no vertices");
  const auto* bytes = reinterpret_cast<const uint8_t*>(data);
  if (size < 2) return absl::DataLossError("vertex part ends inside its bit counts");
  const int position_bits = bytes[0];
  const int normal_bits = bytes[1];
  if (position_bits > 30 || normal_bits == 1 || normal_bits > 30 ||
      (!has_normals && normal_bits != 0)) {
    return absl::DataLossError(absl::StrCat("vertex part: unsupported bits (positions ",
                                            position_bits, ", normals ", normal_bits, ")"));
  }
  size_t at = 2;
  QuantizationBox box;
  if (position_bits > 0) {
    if (size - at < 16) return absl::DataLossError("vertex part ends inside its quantization box");
    std::memcpy(box.origin, data + at, 12);
    std::memcpy(&box.range, data + at + 12, 4);
    at += 16;
    // Every decoded coordinate lies in [origin, origin + range]: finite if both ends are.
    for (int k = 0; k < 3; ++k) {
      if (!std::isfinite(box.origin[k]) || !std::isfinite(box.origin[k] + box.range)) {
        return absl::DataLossError("vertex part: quantization box is not finite");
      }
    }
    if (!(box.range > 0.0f)) return absl::DataLossError("vertex part: quantization range <= 0");
  }

  UninitializedVector<uint32_t> symbols(3 * size_t{vertex_count});

  uint32_t runs = 0;
  if (size - at < 4) return absl::DataLossError("vertex part ends inside its tag run count");
  std::memcpy(&runs, data + at, 4);
  at += 4;
  if (runs == 0 || runs > vertex_count) {
    return absl::DataLossError(
        absl::StrCat("vertex part: ", runs, " tag runs for ", vertex_count, " vertices"));
  }
  uint32_t* run_lengths = symbols.data();
  uint32_t* run_tags = symbols.data() + vertex_count;
  if (!ReadSymbols(data, size, &at, runs, run_lengths) ||
      !ReadSymbols(data, size, &at, runs, run_tags)) {
    return absl::DataLossError("vertex part: tags do not decode");
  }
  out->tags.resize(vertex_count);
  uint8_t tag = 0;
  uint32_t filled = 0;
  for (uint32_t run = 0; run < runs; ++run) {
    if (run_lengths[run] >= vertex_count - filled || run_tags[run] > 255) {
      return absl::DataLossError("vertex part: tag run out of range");
    }
    tag = static_cast<uint8_t>(tag + UnZigZag(run_tags[run]));
    const uint32_t length = run_lengths[run] + 1;
    std::memset(out->tags.data() + filled, tag, length);
    filled += length;
  }
  if (filled != vertex_count)
    return absl::DataLossError("vertex part: tag runs do not cover every vertex");
  uint32_t defined_normals = 0;
  for (uint8_t t : out->tags) defined_normals += !(t & kUndefinedNormalBit);
  if (!has_normals && defined_normals != vertex_count) {
    return absl::DataLossError("vertex part: undefined normals in a chunk without normals");
  }

  out->positions.resize(3 * size_t{vertex_count});
  if (position_bits > 0) {
    if (!ReadSymbols(data, size, &at, 3 * size_t{vertex_count}, symbols.data())) {
      return absl::DataLossError("vertex part: positions do not decode");
    }
    const uint32_t modulus = uint32_t{1} << position_bits;
    const uint32_t max_symbol = MaxSymbol(modulus);
    const float step = box.range / static_cast<float>(modulus - 1);  // as Draco's Dequantizer
    // Both ends of the box being finite is not enough: the top symbol's float(q) * step +
    // origin may round past FLT_MAX. Coordinates grow with q, so the top one bounds them all.
    for (int k = 0; k < 3; ++k) {
      if (!std::isfinite(static_cast<float>(modulus - 1) * step + box.origin[k]))
        return absl::DataLossError("vertex part: quantization box is not finite");
    }
    uint32_t q[3] = {0, 0, 0};
    for (uint32_t v = 0; v < vertex_count; ++v) {
      for (int k = 0; k < 3; ++k) {
        const uint32_t s = symbols[3 * size_t{v} + k];
        if (s > max_symbol) return absl::DataLossError("vertex part: position symbol out of range");
        q[k] = Unwrap(q[k], UnZigZag(s), modulus);
        out->positions[3 * size_t{v} + k] = static_cast<float>(q[k]) * step + box.origin[k];
      }
    }
  } else {
    if (size - at < 12 * size_t{vertex_count}) {
      return absl::DataLossError("vertex part ends inside its float positions");
    }
    std::memcpy(out->positions.data(), data + at, 12 * size_t{vertex_count});
    at += 12 * size_t{vertex_count};
    for (float p : out->positions) {
      if (!std::isfinite(p)) return absl::DataLossError("vertex part: non-finite position");
    }
  }

  out->normals.assign(has_normals ? 3 * size_t{vertex_count} : 0, 0.0f);
  if (has_normals && defined_normals > 0) {
    if (normal_bits > 0) {
      if (!ReadSymbols(data, size, &at, 2 * size_t{defined_normals}, symbols.data())) {
        return absl::DataLossError("vertex part: normals do not decode");
      }
      const uint32_t center = (uint32_t{1} << (normal_bits - 1)) - 1;
      const uint32_t modulus = 2 * center + 1;
      const uint32_t max_symbol = MaxSymbol(modulus);
      const float c = static_cast<float>(center);
      uint32_t st[2] = {center, center};
      size_t n = 0;
      for (uint32_t v = 0; v < vertex_count; ++v) {
        if (out->tags[v] & kUndefinedNormalBit) continue;
        for (int k = 0; k < 2; ++k) {
          const uint32_t s = symbols[n++];
          if (s > max_symbol) return absl::DataLossError("vertex part: normal symbol out of range");
          st[k] = Unwrap(st[k], UnZigZag(s), modulus);
        }
        OctahedralDecode(st[0], st[1], c, &out->normals[3 * size_t{v}]);
      }
    } else {
      if (size - at < 12 * size_t{defined_normals}) {
        return absl::DataLossError("vertex part ends inside its float normals");
      }
      const char* p = data + at;
      for (uint32_t v = 0; v < vertex_count; ++v) {
        if (out->tags[v] & kUndefinedNormalBit) continue;
        float* n = &out->normals[3 * size_t{v}];
        std::memcpy(n, p, 12);
        p += 12;
        if (!std::isfinite(n[0]) || !std::isfinite(n[1]) || !std::isfinite(n[2])) {
          return absl::DataLossError("vertex part: non-finite normal");
        }
      }
      at += 12 * size_t{defined_normals};
    }
  }
  if (at != size) {
    return absl::DataLossError("vertex part: bytes left over after the last attribute");
  }
  return absl::OkStatus();
}

}  // namespace isostream::internal
