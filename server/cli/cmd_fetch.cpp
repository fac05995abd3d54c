// `isostream fetch`: asks a running isostreamd for one frame and writes it, decoded, as PLY.
// The view flags are `extract`'s, so a fetched frame can be compared with a local extraction.
#include <chrono>
#include <cstdio>
#include <iostream>

#include "absl/strings/match.h"
#include "client/net/session_client.h"
#include "server/cli/cli_common.h"
#include "server/cli/commands.h"
#include "server/cli/connection_args.h"
#include "shared/file_io.h"
#include "shared/frame_notes.h"
#include "shared/mesh_weld.h"
#include "shared/number_list.h"
#include "shared/ply_io.h"

namespace isostream::cli {
namespace {

namespace pb = ::isostream::v1;

struct FetchArgs {
  FetchArgs() { connection.timeout_means = "--timeout-s bounds each call, a whole frame included"; }
  ConnectionArgs connection;
  std::string volume;
  ViewArgs view;
  std::string codec = "draco";
  int64_t max_frame_triangles = net::kDefaultMaxFrameTriangles;
  bool progressive = false;
  std::string output;
  bool stats = false;
};

pb::ViewRequest ToViewRequest(const ExtractRequest& r, const FetchArgs& args) {
  pb::ViewRequest v;
  v.set_volume(args.volume);
  v.set_request_id(1);
  for (float iso : r.isovalues) {
    auto* s = v.add_surfaces();
    s->set_isovalue(iso);
    s->set_a(1.0f);
  }
  if (r.budget > 0)
    v.set_triangle_budget(r.budget);
  else
    v.set_eps(r.eps);
  auto* cam = v.mutable_camera();
  if (r.view.orthographic) {
    // The daemon looks along target - eye for orthographic views.
    cam->set_projection(pb::ORTHOGRAPHIC);
    cam->mutable_target()->set_x(r.view.direction.x);
    cam->mutable_target()->set_y(r.view.direction.y);
    cam->mutable_target()->set_z(r.view.direction.z);
  } else {
    cam->set_projection(pb::PERSPECTIVE);
    cam->mutable_eye()->set_x(r.view.eye.x);
    cam->mutable_eye()->set_y(r.view.eye.y);
    cam->mutable_eye()->set_z(r.view.eye.z);
  }
  cam->mutable_up()->set_y(1);
  v.set_codec(args.codec == "raw" ? pb::RAW : pb::DRACO);
  v.set_normals(r.normals == NormalMode::kFlat ? pb::FLAT : pb::SMOOTH);
  v.set_unordered(r.order == DrawOrder::kNone);
  v.set_progressive(args.progressive);
  return v;
}

int RunFetch(const FetchArgs& args) {
  auto fail = [](const std::string& m, int code) {
    std::cerr << "isostream fetch: " << m << "\n";
    return code;
  };
  if (!absl::EndsWithIgnoreCase(args.output, ".ply"))  // as extract and the viewer take names
    return fail("-o must end in .ply, got '" + args.output + "'", 2);
  if (const absl::Status writable = CheckOutputPath(args.output); !writable.ok())
    return fail(std::string(writable.message()), 2);
  // The view's flags, as extract checks them, before any call (a zero --view-dir came back as
  // the server's refusal, exit 1, where extract exits 2 for it).
  if (const absl::Status valid = CheckViewArgs(args.view); !valid.ok())
    return fail(std::string(valid.message()), 2);
  net::ClientOptions options;
  options.max_frame_triangles = args.max_frame_triangles;
  auto client = net::ConnectWith(args.connection, &options);
  if (!client.ok())
    return fail(std::string(client.status().message()), ExitCodeFor(client.status()));

  // The default view (no --eye, no --view-dir) depends on the volume's bounds, and the notes on
  // isovalues on its values, which only the server knows.
  auto info = (*client)->GetVolumeInfo(args.volume, 1);
  if (!info.ok()) return fail(net::ExplainCallError(info.status(), options), 1);
  Volume bounds;
  if (args.view.eye_flag->count() == 0 && args.view.view_dir_flag->count() == 0) {
    for (int a = 0; a < 3 && a < info->dims_size(); ++a) bounds.dims[a] = info->dims(a);
    bounds.spacing = {info->spacing().x(), info->spacing().y(), info->spacing().z()};
    bounds.origin = {info->origin().x(), info->origin().y(), info->origin().z()};
  }
  auto request = MakeRequest(args.view, bounds);
  if (!request.ok()) return fail(std::string(request.status().message()), 2);
  const bool some_inside = NoteIsovaluesOutside("isostream fetch", request->isovalues,
                                                info->min_value(), info->max_value(), args.volume);

  auto frame = (*client)->Fetch(ToViewRequest(*request, args));
  if (!frame.ok()) return fail(net::ExplainCallError(frame.status(), options), 1);
  // Smooth normals share vertices, as extract writes them: each chunk carried its own copy of
  // its seams'. (Flat ones are not shared by the extractor either.)
  if (request->normals == NormalMode::kSmooth)
    WeldIdenticalVertices(&frame->mesh, frame->chunk_first_vertex);
  const absl::Status written = WritePly(frame->mesh, args.output);
  if (!written.ok()) return fail(std::string(written.message()), 1);
  if (args.stats) {
    const pb::FrameStats& s = frame->stats;
    std::printf("triangles     %lld  (vertices on the server %lld)\n", (long long)s.triangles(),
                (long long)s.vertices());
    std::printf("eps used      %s\n", ShortestText(s.eps_used()).c_str());
    if (s.triangle_budget() > 0)
      std::printf("budget        %lld%s\n", (long long)s.triangle_budget(),
                  s.triangle_budget() < request->budget ? "  (the daemon's frame limit)" : "");
    std::printf("chunks        %d, %lld bytes (%.2f bytes/triangle)\n", frame->chunks,
                (long long)frame->bytes,
                s.triangles() > 0 ? double(frame->bytes) / double(s.triangles()) : 0.0);
    std::printf("ms            extract %.1f  encode %.1f (summed over chunks)  frame %.1f\n",
                s.extract_ms(), s.encode_ms(), s.frame_ms());
  }
  const std::string note =
      FrameNote(int64_t(frame->mesh.triangle_count()), request->budget,
                frame->stats.triangle_budget(), frame->stats.eps_used(), some_inside);
  if (!note.empty()) std::cerr << "isostream fetch: note: " << note << "\n";
  std::fprintf(stderr, "wrote %s: %zu triangles %s (eps %s)\n", args.output.c_str(),
               frame->mesh.triangle_count(),
               args.view.order == "none" ? "unordered" : "in back-to-front order",
               ShortestText(frame->stats.eps_used()).c_str());
  return 0;
}

}  // namespace

CLI::App* AddFetchCommand(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "fetch", "Ask a running isostreamd for one frame and write it (decoded) as PLY");
  auto args = std::make_shared<FetchArgs>();
  AddConnectionOptions(cmd, &args->connection,
                       "each call (the volume's facts, then the whole frame) fails after this "
                       "many seconds, connecting included (default 60; 0: wait forever)");
  cmd->add_option("--volume", args->volume,
                  "catalogue name (or a generator spec such as "
                  "buckyball:129 when the daemon has no catalogue)")
      ->required();
  AddViewOptions(cmd, &args->view);
  cmd->add_option("--codec", args->codec, "draco (default) or raw")
      ->check(CLI::IsMember({"draco", "raw"}));
  cmd->add_option("--max-frame-triangles", args->max_frame_triangles,
                  "refuse a frame past this many triangles (default 2^26)")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 40));
  cmd->add_flag("--progressive", args->progressive, "let the server send a coarse frame first");
  cmd->add_option("-o,--output", args->output, "out.ply")->required();
  cmd->add_flag("--stats", args->stats, "print counts, sizes and timings");
  cmd->callback([args, exit_code] { *exit_code = RunFetch(*args); });
  return cmd;
}

}  // namespace isostream::cli
