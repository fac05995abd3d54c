// glTF 2.0 binary (.glb) output of an OrderedMesh, for viewers and the web.
//
// The file holds one mesh with ONE primitive whose triangles are in the mesh's draw order:
// splitting by surface into several primitives would make viewers draw surface by surface and
// break the back-to-front order across surfaces. The primitive is compressed with
// KHR_draco_mesh_compression (listed in extensionsUsed and extensionsRequired) using Draco's
// sequential encoding, the one Draco method that keeps face order. Attributes:
//   POSITION  float VEC3 (quantized by Draco; accessor min/max are the decoded bounds)
//   NORMAL    float VEC3, when the mesh has normals (zero normals come back as some unit
//             vector: glTF has no "undefined normal")
//   _SURFACE  UNSIGNED_BYTE SCALAR, the triangle's surface index carried per vertex
//   COLOR_0   UNSIGNED_BYTE VEC4 normalized, the surface colour, when colours are given
// Vertices shared by two surfaces are duplicated, so per-vertex surface data is exact. The
// material uses alphaMode BLEND and doubleSided true: isosurfaces are viewed translucent from
// both sides.
#pragma once

#include <array>
#include <string>
#include <string_view>
#include <vector>

#include "shared/frame_codec.h"
#include "shared/ordered_mesh.h"
#include "shared/status.h"

namespace isostream {

struct GlbOptions {
  // RGBA in [0, 1] per surface index. When non-empty every vertex gets COLOR_0 from its surface
  // (opaque white for surfaces beyond the list); when empty COLOR_0 is omitted.
  std::vector<std::array<float, 4>> surface_colors;
  // Quantization used for the Draco primitive. compress_connectivity applies as in the frame
  // codec.
  CodecOptions codec;
  // Meters per unit of the mesh's coordinates (Volume::meters_per_unit), 0 if unknown. glTF's
  // unit is the meter: a known unit other than it becomes the node's scale, the vertices
  // staying as they are; an unknown one leaves the coordinates to be read as meters.
  double meters_per_unit = 0;
};

// Serializes `mesh` as GLB bytes into `out` (replaced). Returns InvalidArgument if the mesh
// fails ValidateMesh or the options are out of range. An empty mesh gives a valid file with an
// empty scene.
//
// The Draco buffer view is zero-padded to at least 3 bytes per face + 64 because Draco 1.5.5
// decoders (including the WebAssembly builds viewers ship) reject compressed sequential
// connectivity in a shorter buffer; the padding is never read.
absl::Status SerializeGlb(const OrderedMesh& mesh, const GlbOptions& options, std::string* out);

// SerializeGlb to the file at `path` (created or truncated); nothing is written on invalid
// input. I/O failures return a status naming the path.
absl::Status WriteGlb(const OrderedMesh& mesh, const std::string& path,
                      const GlbOptions& options = {});

// The two chunks of a GLB container.
struct GlbChunks {
  std::string json;
  std::string bin;  // empty when the file has no BIN chunk
};

// Splits GLB bytes into their JSON and BIN chunks, checking the container: magic, version 2,
// declared length, chunk types, lengths and alignment. InvalidArgument on any mismatch.
absl::StatusOr<GlbChunks> ParseGlbChunks(std::string_view bytes);

// Reads back a GLB in the layout SerializeGlb writes (one primitive compressed with
// KHR_draco_mesh_compression, _SURFACE attribute) into an OrderedMesh with the same triangle
// order, its positions as stored (a node's scale to meters is not applied). Meant for tests and
// scripts, not as a general glTF loader: other layouts return Unimplemented or InvalidArgument.
absl::StatusOr<OrderedMesh> ParseGlb(std::string_view bytes);

}  // namespace isostream
