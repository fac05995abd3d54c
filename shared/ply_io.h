// PLY files for OrderedMesh: the interchange format for scripts and for opening frames in
// MeshLab or Blender. Face order in a file is draw order, so a file written from a frame can be
// drawn back to front by drawing its faces first to last.
//
// Layout written (and the layout ReadPly expects, although it accepts more, see ParsePly):
//   element vertex N: property float x, y, z, nx, ny, nz
//   element face M:   property list uchar uint vertex_indices; property uchar surface
#pragma once

#include <string>
#include <string_view>

#include "shared/ordered_mesh.h"
#include "shared/status.h"

namespace isostream {

// Serializes `mesh` to PLY bytes in `out` (replacing its contents). binary=true gives
// binary_little_endian; binary=false gives ascii with each float printed in its shortest form
// that reads back to the same value, so both forms round-trip exactly. Empty mesh.normals are
// written as zero normals. Returns InvalidArgument (and leaves `out` unspecified) if the mesh
// fails ValidateMesh.
absl::Status SerializePly(const OrderedMesh& mesh, bool binary, std::string* out);

// SerializePly to the file at `path` (created or truncated). Nothing is written when the mesh
// is invalid; an I/O failure returns a status carrying the path and the system's reason.
absl::Status WritePly(const OrderedMesh& mesh, const std::string& path, bool binary = true);

// Parses PLY bytes. Accepted: format ascii 1.0 or binary_little_endian 1.0 (big endian is
// rejected as unsupported); a "vertex" element with x, y, z of any scalar type and optionally
// nx, ny, nz (zero normals when absent); a "face" element with a list property named
// vertex_indices or vertex_index holding exactly 3 indices per face, and optionally a scalar
// "surface" (0 when absent). Other elements and properties are skipped. Triangles keep file
// order. Errors (InvalidArgument unless noted) name the problem and where: bad header,
// non-triangle face, index out of range, surface >= kMaxSurfaces, non-finite coordinate;
// DataLoss for data that ends early.
absl::StatusOr<OrderedMesh> ParsePly(std::string_view bytes);

// ParsePly on the contents of the file at `path`; NotFound if it does not exist. Messages are
// prefixed with the path.
absl::StatusOr<OrderedMesh> ReadPly(const std::string& path);

}  // namespace isostream
