// The view half of a traversal Context: the eye or direction in grid space and, per class,
// the separating-plane tests that order children (§4.2). Shared by extraction and by the
// re-ordering of a retained cut, which must decide exactly as a fresh extraction would.
// Private to server/extract.
#pragma once

#include "server/extract/extract_request.h"
#include "server/extract/tree_node.h"

namespace isostream::extract_internal {

// Sets c->ordered, orthographic, eye, dir and the plane tables for `view` and `order`; c->k
// must be set.
void SetView(Context* c, const GridToWorld& xf, const View& view, DrawOrder order);

}  // namespace isostream::extract_internal
