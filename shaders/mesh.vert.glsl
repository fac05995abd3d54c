#version 330 core
// Positions and normals are already in world units; shading happens in world space so that
// the fragment stage needs no normal matrix.

layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
// The triangle's surface, repeated on each of its vertices (see mesh_renderer_gl.cpp).
layout(location = 2) in uint a_surface;

uniform mat4 u_view_projection;
uniform vec3 u_eye;
// 1 / the eye's distance to its target: the vector to the eye in units of the view's own size,
// so its square neither underflows nor overflows for volumes of any size floats can place.
uniform float u_view_scale;

out vec3 v_to_eye;
out vec3 v_normal;
flat out uint v_surface;

void main() {
  v_to_eye = (u_eye - a_position) * u_view_scale;
  v_normal = a_normal;
  v_surface = a_surface;
  gl_Position = u_view_projection * vec4(a_position, 1.0);
}
