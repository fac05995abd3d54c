// Merging vertices that are the same vertex written more than once: a streamed frame's chunks
// each carry their own copy of the vertices on their seams (they decode identically: positions
// are quantized on the volume's box), so a frame assembled from them is open along the seams to
// any check by index, where the extractor's mesh is closed.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "shared/ordered_mesh.h"

namespace isostream {

// Makes a vertex one with a bit-identical vertex (position and normal) of an earlier part, never
// of its own: parts are the vertex ranges starting at `part_first_vertex` (ascending; a
// chunk's vertices are distinct even where quantization made two alike, and merging those made
// triangles with a repeated corner). A value that two vertices of one part share is welded
// nowhere: a later part's copy could be of either (welding it to the first made edges used 1
// to 6 times). The kept vertices keep their order; the triangles and their order are
// unchanged. Returns how many vertices went.
size_t WeldIdenticalVertices(OrderedMesh* mesh, const std::vector<uint32_t>& part_first_vertex);

}  // namespace isostream
