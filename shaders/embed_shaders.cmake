# Turns GLSL files into one C++ source with a lookup by file name, so binaries carry their
# shaders and run from any directory. Run as a build step (cmake -P) so that editing a shader
# rebuilds without reconfiguring.
#   -DOUTPUT=<generated .cpp>  -DSHADERS=<;-separated list of .glsl files>
if(NOT OUTPUT OR NOT SHADERS)
  message(FATAL_ERROR "embed_shaders.cmake needs -DOUTPUT and -DSHADERS")
endif()

set(delimiter "isostream_glsl")
set(body "")
foreach(path IN LISTS SHADERS)
  get_filename_component(name "${path}" NAME)
  file(READ "${path}" source)
  string(FIND "${source}" ")${delimiter}\"" clash)
  if(NOT clash EQUAL -1)
    message(FATAL_ERROR "${path} contains the raw string delimiter ${delimiter}")
  endif()
  string(APPEND body "  if (name == \"${name}\") return R\"${delimiter}(${source})${delimiter}\";\n")
endforeach()

set(content "// Generated from shaders/*.glsl by shaders/embed_shaders.cmake. Do not edit.
#include \"client/render/opengl/embedded_shaders.h\"

namespace isostream::render::shaders {

std::string_view EmbeddedShader(std::string_view name) {
${body}  return {};
}

}  // namespace isostream::render::shaders
")

# Rewriting an unchanged file would recompile it on every build.
if(EXISTS "${OUTPUT}")
  file(READ "${OUTPUT}" old)
  if(old STREQUAL content)
    return()
  endif()
endif()
file(WRITE "${OUTPUT}" "${content}")
