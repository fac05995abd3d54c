#version 330 core
// Positions and normals are already in world units; shading happens in world space so that
// the fragment stage needs no normal matrix.

layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
// The triangle's surface, repeated on each of its vertices (see mesh_renderer_gl.cpp).
layout(location = 2) in uint a_surface;

uniform mat4 u_view_projection;

out vec3 v_position;
out vec3 v_normal;
flat out uint v_surface;

void main() {
  v_position = a_position;
  v_normal = a_normal;
  v_surface = a_surface;
  gl_Position = u_view_projection * vec4(a_position, 1.0);
}
