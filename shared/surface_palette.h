// The default colour and opacity of each surface, by its index in the request: what the viewer
// draws with and what the CLI's GLB carries per vertex, so a file opened elsewhere looks as the
// viewer shows it. Gerstner's Fig. 5 for the first three surfaces (outer to inner: blue 0.3,
// red 0.5, green 0.7), then thirteen more colours chosen to stay apart from those and each
// other, at opacity 0.5.
#pragma once

#include <array>

#include "shared/ordered_mesh.h"

namespace isostream {

// Linear RGB and opacity, each in [0, 1].
inline constexpr std::array<std::array<float, 4>, kMaxSurfaces> kDefaultSurfaceRgba = {{
    {0.15f, 0.35f, 0.95f, 0.3f},  // blue   (outermost)
    {0.90f, 0.15f, 0.10f, 0.5f},  // red
    {0.10f, 0.75f, 0.20f, 0.7f},  // green  (innermost of the three)
    {0.95f, 0.80f, 0.10f, 0.5f},  // yellow
    {0.80f, 0.20f, 0.75f, 0.5f},  // magenta
    {0.10f, 0.75f, 0.85f, 0.5f},  // cyan
    {1.00f, 0.50f, 0.05f, 0.5f},  // orange
    {0.45f, 0.20f, 0.70f, 0.5f},  // purple
    {0.00f, 0.50f, 0.50f, 0.5f},  // teal
    {0.55f, 0.33f, 0.15f, 0.5f},  // brown
    {1.00f, 0.60f, 0.70f, 0.5f},  // pink
    {0.50f, 0.50f, 0.00f, 0.5f},  // olive
    {0.10f, 0.10f, 0.45f, 0.5f},  // navy
    {0.50f, 0.50f, 0.50f, 0.5f},  // grey
    {0.60f, 0.95f, 0.20f, 0.5f},  // lime
    {0.50f, 0.05f, 0.15f, 0.5f},  // maroon
}};

}  // namespace isostream
