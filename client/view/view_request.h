// What the viewer asks the daemon for: one place that turns the viewer's state (camera,
// isovalues, accuracy) into a ViewRequest, for the headless and the window paths alike.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "client/net/session_client.h"
#include "client/render/camera.h"
#include "client/render/mesh_renderer.h"

namespace isostream::view {

struct ViewState {
  std::string volume;
  std::vector<double> isovalues;
  double eps = 0;  // used when budget < 0
  int64_t budget = -1;
  bool raw_codec = false;
  bool progressive = true;
};

inline ::isostream::v1::ViewRequest MakeViewRequest(const ViewState& state,
                                                    const render::Camera& camera,
                                                    const render::Palette& palette,
                                                    uint64_t request_id) {
  ::isostream::v1::ViewRequest view;
  view.set_volume(state.volume);
  view.set_request_id(request_id);
  auto set = [](::isostream::v1::Vec3* out, const glm::vec3& v) {
    out->set_x(v.x);
    out->set_y(v.y);
    out->set_z(v.z);
  };
  set(view.mutable_camera()->mutable_eye(), camera.eye);
  set(view.mutable_camera()->mutable_target(), camera.target);
  set(view.mutable_camera()->mutable_up(), camera.up);
  for (size_t s = 0; s < state.isovalues.size(); ++s) {
    auto* surface = view.add_surfaces();
    surface->set_isovalue(float(state.isovalues[s]));
    const render::SurfaceStyle& style = palette[s % palette.size()];
    surface->set_r(style.color.r);
    surface->set_g(style.color.g);
    surface->set_b(style.color.b);
    surface->set_a(style.opacity);
  }
  if (state.budget >= 0) {
    view.set_triangle_budget(state.budget);
  } else {
    view.set_eps(state.eps);
  }
  view.set_codec(state.raw_codec ? ::isostream::v1::RAW : ::isostream::v1::DRACO);
  view.set_progressive(state.progressive);
  return view;
}

}  // namespace isostream::view
