// Merging vertices that are the same vertex written more than once: a streamed frame's chunks
// each carry their own copy of the vertices on their seams (they decode identically: positions
// are quantized on the volume's box), so a frame assembled from them is open along the seams to
// any check by index, where the extractor's mesh is closed.
#pragma once

#include "shared/ordered_mesh.h"

namespace isostream {

// Makes vertices with bit-identical positions and normals one (the first keeps its index
// order; the triangles and their order are unchanged). Returns how many vertices went.
size_t WeldIdenticalVertices(OrderedMesh* mesh);

}  // namespace isostream
