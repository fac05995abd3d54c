// The GLSL sources in shaders/, compiled into the binary at build time.
#pragma once

#include <string_view>

namespace isostream::render::shaders {

// The source of shaders/<name> (e.g. "mesh.vert.glsl") as it was at build time; empty when no
// such shader was embedded.
std::string_view EmbeddedShader(std::string_view name);

}  // namespace isostream::render::shaders
