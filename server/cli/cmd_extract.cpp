// `isostream extract`: one view-ordered adaptive extraction to PLY or glTF (.glb).
#include <cstdio>
#include <iostream>

#include "absl/strings/match.h"
#include "server/cli/cli_common.h"
#include "server/cli/commands.h"
#include "server/extract/extractor.h"
#include "server/volume/quantization.h"
#include "shared/file_io.h"
#include "shared/frame_notes.h"
#include "shared/glb_writer.h"
#include "shared/number_list.h"
#include "shared/ply_io.h"
#include "shared/surface_palette.h"

namespace isostream::cli {
namespace {

struct ExtractArgs {
  VolumeArgs volume;
  ViewArgs view;
  std::string output;
  bool stats = false;
};

void PrintStats(const ExtractRequest& r, const ExtractStats& s, const PreparedVolume& p) {
  std::printf("triangles     %lld  (vertices %lld)\n", (long long)s.triangles,
              (long long)s.vertices);
  for (size_t i = 0; i < r.isovalues.size(); ++i)
    std::printf("  surface %zu   iso %-10g %lld triangles\n", i, r.isovalues[i],
                (long long)s.triangles_per_surface[i]);
  std::printf("eps used      %s%s\n", ShortestText(s.eps_used).c_str(),
              r.budget == 0             ? ""
              : s.triangles <= r.budget ? "  (found for the budget)"
                                        : "  (the coarsest mesh, over the budget)");
  std::printf("tets visited  %lld  (leaves with triangles %lld, subtrees %d)\n",
              (long long)s.tets_visited, (long long)s.leaves, s.subtrees);
  std::printf("ms            load %.1f  pad %.1f  hierarchy %.1f (cache %s)\n", p.load_s * 1e3,
              p.pad_s * 1e3, p.hierarchy_s * 1e3, CacheOutcomeName(p.cache));
  std::printf(
      "ms extract    budget %.1f (%d passes)  split %.1f  traverse %.1f  join %.1f  total %.1f\n",
      s.budget_ms, s.budget_passes, s.split_ms, s.extract_ms, s.join_ms, s.total_ms);
}

int RunExtract(const ExtractArgs& args) {
  const bool glb = absl::EndsWithIgnoreCase(args.output, ".glb");
  if (!glb && !absl::EndsWithIgnoreCase(args.output, ".ply")) {
    std::cerr << "isostream extract: -o must end in .ply or .glb, got '" << args.output << "'\n";
    return 2;
  }
  // Before the volume is prepared and the frame extracted, which may take minutes.
  if (const absl::Status out = CheckOutputPath(args.output); !out.ok()) {
    std::cerr << "isostream extract: " << out.message() << "\n";
    return 2;
  }
  // The view's flags too: a typo in --iso was reported after minutes of preparing a large
  // volume.
  if (const absl::Status valid = CheckViewArgs(args.view); !valid.ok()) {
    std::cerr << "isostream extract: " << valid.message() << "\n";
    return 2;
  }
  if (const absl::Status spec = CheckVolumeSpec(args.volume); !spec.ok()) {
    std::cerr << "isostream extract: " << spec.message() << "\n";
    return 2;
  }
  auto prepared = Prepare(args.volume);
  if (!prepared.ok()) {
    std::cerr << "isostream extract: " << prepared.status().message() << "\n";
    return 1;
  }
  auto request = MakeRequest(args.view, *prepared->volume);
  if (!request.ok()) {
    std::cerr << "isostream extract: " << request.status().message() << "\n";
    return 2;
  }
  request->threads = args.volume.threads;
  const bool some_inside =
      NoteIsovaluesOutside("isostream extract", request->isovalues, prepared->volume->min_value,
                           prepared->volume->max_value, args.volume.volume);
  auto result = Extract(*prepared->hierarchy, prepared->grid_to_world, *request);
  if (!result.ok()) {
    std::cerr << "isostream extract: " << result.status().message() << "\n";
    return 2;
  }
  // As fine as the daemon's frames (1/64 voxel): the writer's default, 14 bits over the mesh's
  // bounding cube, put two corners of 1.2% of cayley:257's triangles at eps 0 in one place.
  GlbOptions glb_options;
  QuantizationBox box;
  QuantizationFor(*prepared->volume, &box, &glb_options.codec.position_bits);
  glb_options.codec.position_box = box;
  glb_options.meters_per_unit = prepared->volume->meters_per_unit;
  // Each surface in the viewer's default colour and opacity (COLOR_0), so the file opened in
  // Blender or three.js tells the surfaces apart as the viewer does.
  for (size_t i = 0; i < request->isovalues.size(); ++i)
    glb_options.surface_colors.push_back(kDefaultSurfaceRgba[i]);
  const absl::Status written =
      glb ? WriteGlb(result->mesh, args.output, glb_options) : WritePly(result->mesh, args.output);
  if (!written.ok()) {
    std::cerr << "isostream extract: " << written.message() << "\n";
    return 1;
  }
  if (args.stats) PrintStats(*request, result->stats, *prepared);
  const std::string note =
      FrameNote(result->stats.triangles, request->budget, request->budget, result->stats.eps_used,
                some_inside);  // no daemon: fitted to the budget
  if (!note.empty()) std::cerr << "isostream extract: note: " << note << "\n";
  std::fprintf(stderr, "wrote %s: %lld triangles %s (eps %s)\n", args.output.c_str(),
               (long long)result->stats.triangles,
               request->order == DrawOrder::kNone ? "unordered" : "in back-to-front order",
               ShortestText(result->stats.eps_used).c_str());
  return 0;
}

}  // namespace

CLI::App* AddExtractCommand(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "extract",
      "Extract transparent isosurfaces, triangles in back-to-front order, to PLY or GLB");
  auto args = std::make_shared<ExtractArgs>();
  AddVolumeOptions(cmd, &args->volume);
  AddViewOptions(cmd, &args->view);
  cmd->add_option("-o,--output", args->output, "out.ply or out.glb")->required();
  cmd->add_flag("--stats", args->stats, "print counts and timings");
  cmd->callback([args, exit_code] { *exit_code = RunExtract(*args); });
  return cmd;
}

}  // namespace isostream::cli
