// A reference picture for the golden tests, made without OpenGL: Embree finds every surface a
// pixel's ray crosses, each crossing is shaded with MeshRenderer's documented formula, and the
// crossings are composited exactly in depth order, farthest first, over the background. The
// rasterized frame must match it when its draw order is a valid painter's order.
#pragma once

#include <glm/vec4.hpp>

#include "client/render/camera.h"
#include "client/render/image.h"
#include "client/render/mesh_renderer.h"
#include "shared/ordered_mesh.h"
#include "shared/status.h"

namespace isostream::render::testing {

// One ray per pixel centre, clipped to the camera's near and far planes like the rasterizer.
// Internal when Embree cannot make a device or scene.
absl::StatusOr<Image> TraceReference(const OrderedMesh& mesh, const Camera& camera, int width,
                                     int height, const Palette& palette, const Lighting& lighting,
                                     const glm::vec4& background);

}  // namespace isostream::render::testing
