// isostream-view --window: an interactive window (GLFW). Dragging orbits the eye around the
// volume, the wheel zooms, +/- halve or double eps, [ and ] move every isovalue by 1% of the
// value range, R resets, Q or Esc quits. Every change sends a new view on the same Session
// (the daemon cancels the frame in progress); chunks are drawn as they arrive, and the shown
// frame is replaced only when the next one is complete.
#pragma once

#include <string>

#include "client/net/session_client.h"
#include "client/view/view_request.h"

namespace isostream::view {

struct WindowOptions {
  int width = 1024;
  int height = 768;
  ViewState state;
  render::Camera camera;        // initial eye and target; orbiting keeps the target
  glm::vec3 world_up{0, 1, 0};  // the vertical (--up): orbits turn about it
  int samples = 4;              // multisample anti-aliasing (--samples), where the display has it
  double value_range = 1;       // max - min of the volume, for the isovalue keys
  float scene_radius = 1;       // of the volume's bounding sphere: near and far follow the zoom
  // For tests and scripts: close after this many refined frames have been shown, writing a
  // screenshot of the last one to `screenshot` (if not empty). 0: run until closed.
  int exit_after_frames = 0;
  std::string screenshot;
  // Turn the view by 1/orbit of a full turn about the vertical after each refined frame, until
  // `orbit` views are drawn (0: only the user moves it): a scripted run of --exit-after N > 1
  // otherwise never got past its first frame.
  int orbit = 0;
  // With exit_after_frames: fail after this long without data while a frame is awaited, or
  // without a move once the frames so far are in (0: never), so neither a stalled daemon nor a
  // count no move will reach holds a script.
  int timeout_s = 0;
};

// Unavailable with a clear message when no window can be opened (no display, no GL 3.3).
absl::Status RunWindow(net::Client& client, const WindowOptions& options);

}  // namespace isostream::view
