// Internal to shared/: building, encoding and decoding the Draco mesh that both the frame codec
// and the GLB writer carry. Keeps Draco's headers out of shared/'s public headers.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "shared/frame_codec.h"
#include "shared/internal/chunk_gather.h"
#include "shared/ordered_mesh.h"
#include "shared/status.h"

namespace isostream::internal {

inline constexpr uint8_t kSurfaceMask = 0x7f;
inline constexpr uint8_t kUndefinedNormalBit = 0x80;

struct DracoEncodeSettings {
  int position_bits = 14;
  int normal_bits = 10;
  bool compress_connectivity = true;
  const QuantizationBox* position_box = nullptr;  // explicit quantization grid when set
  // Set kUndefinedNormalBit in the surface attribute of vertices whose normal is (0, 0, 0).
  // The GLB writer leaves it clear so that _SURFACE holds plain surface indices.
  bool mark_undefined_normals = true;
  // When non-empty, adds a COLOR attribute (uint8 x4, normalized) with each vertex's surface
  // colour; surfaces beyond the list get opaque white.
  std::vector<std::array<uint8_t, 4>> surface_colors;
};

// Draco attribute unique ids, as glTF's KHR_draco_mesh_compression refers to them; -1 = absent.
struct DracoAttributeIds {
  int position = -1;
  int normal = -1;
  int surface = -1;
  int color = -1;
};

// Range checks on CodecOptions (bits, box); InvalidArgument naming the bad field.
absl::Status CheckCodecOptions(const CodecOptions& options);

// InvalidArgument unless every position of `chunk` maps into `box`'s quantization grid.
absl::Status CheckInsideBox(const GatheredChunk& chunk, const QuantizationBox& box);

// Encodes `chunk` (at least one triangle) with MESH_SEQUENTIAL_ENCODING into `out` (replaced).
// Options must already be range-checked. Returns the attribute ids in `ids` when non-null.
absl::Status EncodeDracoMesh(const GatheredChunk& chunk, const DracoEncodeSettings& settings,
                             std::string* out, DracoAttributeIds* ids);

// Appends the vertex attributes of `chunk` (at least one vertex) to `out` as a Draco point
// cloud written with POINT_CLOUD_SEQUENTIAL_ENCODING (point order kept), with the same
// attributes and quantization as EncodeDracoMesh.
absl::Status EncodeDracoPoints(const GatheredChunk& chunk, const DracoEncodeSettings& settings,
                               std::string* out);

// Reads Draco's own header at the start of data[0, size): must be a triangular mesh written
// with sequential encoding and no metadata. Returns its face and point counts, so callers can
// compare them with what they expect before Draco allocates for them.
absl::Status ReadDracoSequentialCounts(const char* data, size_t size, uint32_t* face_count,
                                       uint32_t* point_count);

// As ReadDracoSequentialCounts for a point cloud written by EncodeDracoPoints: checks the
// header (sequential point cloud, no metadata) and returns its point count.
absl::Status ReadDracoPointCloudCount(const char* data, size_t size, uint32_t* point_count);

// Decodes the Draco mesh in data[0, size), which must hold exactly `triangle_count` faces and
// `vertex_count` points (checked against Draco's header before decoding) and a NORMAL
// attribute iff `expect_normals`. Appends to `append_to` as DecodeChunk documents; on error
// `append_to` is unchanged. Works around Draco 1.5.5 rejecting compressed-connectivity buffers
// shorter than 3 bytes per face by decoding from a zero-padded copy when needed.
absl::Status DecodeDracoMesh(const char* data, size_t size, uint32_t triangle_count,
                             uint32_t vertex_count, bool expect_normals, OrderedMesh* append_to);

// Checks that each triangle's corners (local indices, already checked against the vertex
// count) agree on a valid surface, then appends `chunk` to `append_to` as DecodeChunk
// documents; on error `append_to` is unchanged.
absl::Status AppendDecodedChunk(DecodedChunk* chunk, OrderedMesh* append_to);

// Decodes the point cloud in data[0, size) written by EncodeDracoPoints, which must hold
// exactly `vertex_count` points (checked against Draco's header before decoding) and a NORMAL
// attribute iff `expect_normals`, and appends it with `triangles` (local indices, 3 per
// triangle) to `append_to` as DecodeDracoMesh does; on error `append_to` is unchanged.
absl::Status DecodeDracoPoints(const char* data, size_t size, std::vector<uint32_t> triangles,
                               uint32_t vertex_count, bool expect_normals, OrderedMesh* append_to);

}  // namespace isostream::internal
