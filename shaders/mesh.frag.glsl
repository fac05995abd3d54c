#version 330 core
// Two-sided Blinn-Phong with a headlight; the formula is spelled out in
// client/render/mesh_renderer.h and must stay in step with it.

in vec3 v_to_eye;  // in units of the eye's distance to its target
in vec3 v_normal;
flat in uint v_surface;

uniform vec4 u_surface_style[16];  // rgb colour, opacity

uniform vec3 u_forward;
uniform bool u_orthographic;
uniform vec3 u_light;         // unit, world space
uniform vec4 u_light_terms;   // ambient, diffuse, specular, shininess

out vec4 frag_color;

void main() {
  vec4 style = u_surface_style[min(v_surface, 15u)];

  vec3 v = u_orthographic ? -u_forward : normalize(v_to_eye);
  vec3 n = v_normal;
  // Zero normals mean "undefined" in OrderedMesh; the facet normal keeps such meshes lit (the
  // position's derivatives, negated and scaled alike: the same direction).
  if (dot(n, n) < 1e-12) n = cross(dFdx(v_to_eye), dFdy(v_to_eye));
  n = normalize(n);
  if (dot(n, v) < 0.0) n = -n;

  vec3 h = normalize(u_light + v);
  float lambert = max(dot(n, u_light), 0.0);
  float highlight = pow(max(dot(n, h), 0.0), u_light_terms.w);
  vec3 rgb = style.rgb * (u_light_terms.x + u_light_terms.y * lambert) + u_light_terms.z * highlight;
  frag_color = vec4(min(rgb, vec3(1.0)), style.a);
}
