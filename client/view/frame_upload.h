// One step of showing a streamed frame, for the headless and the window paths alike: a chunk
// goes into the frame assembler, and what it adds is uploaded to the renderer's pending frame
// (opened at a frame's first chunk).
#pragma once

#include <cstddef>

#include "client/net/session_client.h"
#include "client/render/mesh_renderer.h"
#include "shared/status.h"

namespace isostream::view {

inline absl::Status AddAndUpload(net::FrameAssembler& assembler,
                                 const ::isostream::v1::FrameChunk& chunk,
                                 render::MeshRenderer& renderer, bool* frame_open) {
  const bool starts = chunk.chunk_index() == 0;
  // A frame's first chunk starts a new mesh in the assembler: its triangles count from 0,
  // whatever the frame before it held. (Counting from the last frame's size dropped the first
  // chunk of every refined frame that followed a larger coarse one, and in the window of every
  // frame that followed a larger one.)
  const size_t before = starts ? 0 : assembler.frame().mesh.triangle_count();
  ISOSTREAM_RETURN_IF_ERROR(assembler.Add(chunk));
  if (starts) {
    renderer.BeginFrame();
    *frame_open = true;
  }
  const net::Frame& f = assembler.frame();
  if (*frame_open && f.mesh.triangle_count() > before)
    return renderer.AddChunk(f.mesh, before, f.mesh.triangle_count() - before);
  return absl::OkStatus();
}

}  // namespace isostream::view
