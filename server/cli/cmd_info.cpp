// `isostream info --volume SPEC [--iso ...]`: load a volume, build (or load) its hierarchy,
// print facts; with isovalues, how many triangles each eps gives.
#include <chrono>
#include <cstdio>
#include <iostream>
#include <thread>
#include <utility>

#include "server/cli/cli_common.h"
#include "server/cli/commands.h"
#include "server/extract/extractor.h"
#include "shared/frame_notes.h"
#include "shared/given_number.h"
#include "shared/number_list.h"

namespace isostream::cli {
namespace {

// For --iso: the triangle count at each octave of eps, from one counting pass at eps 0 (the
// count changes only at the hierarchy's eta codes, CountTrianglesPerEtaCode), down to where it
// reaches the full-resolution count.
int PrintCountsByEps(const PreparedVolume& prepared, ExtractRequest r,
                     const std::string& iso_text) {
  const uint32_t top = CoarsestEtaCode(*prepared.hierarchy);
  const auto t0 = std::chrono::steady_clock::now();
  auto counts = CountTrianglesPerEtaCode(*prepared.hierarchy, prepared.grid_to_world, r, 0, top);
  if (!counts.ok()) {
    std::cerr << "isostream info: " << counts.status().message() << "\n";
    return 2;
  }
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  std::printf("triangles by eps  (isovalues %s; one counting pass, %.0f ms)\n", iso_text.c_str(),
              ms);
  std::printf("  %-16s  %s\n", "eps", "triangles");
  const int64_t full = (*counts)[0];
  // The same count at every eps (no triangle anywhere, or data so flat the root's eta is 0,
  // whose row read "9.183549615799121e-41  0"): one row says so.
  if ((*counts)[top] == full) {
    std::printf("  %-16s  %lld\n", "any", (long long)full);
    return 0;
  }
  uint32_t code = top;
  int64_t shown = -1;
  for (;; code = code > kEtaCodesPerOctave ? code - kEtaCodesPerOctave : 0) {
    // An octave that adds nothing is not a row (the count may stay put for dozens of octaves
    // of tiny eps, down to eps 0).
    if ((*counts)[code] != shown) {
      std::printf("  %-16s  %lld\n", ShortestText(EtaCodeEps(code)).c_str(),
                  (long long)(*counts)[code]);
      shown = (*counts)[code];
    }
    // Past 99% of the full-resolution count the octaves add little: that count closes.
    if (code == 0 || 100 * (*counts)[code] >= 99 * full) break;
  }
  // Closed by eps 0's count.
  if (code != 0) std::printf("  %-16s  %lld\n", "0", (long long)full);
  return 0;
}

int RunInfo(const VolumeArgs& args, const std::string& iso) {
  // The isovalues are checked before the volume is prepared, which may take minutes.
  ExtractRequest counting;
  counting.threads = args.threads;
  if (!iso.empty()) {
    auto parsed = ParseIsovalues(iso);
    absl::Status valid = parsed.status();
    if (parsed.ok()) {
      counting.isovalues = std::move(*parsed);
      valid = ValidateRequest(counting);
    }
    if (!valid.ok()) {
      std::cerr << "isostream info: " << valid.message() << "\n";
      return 2;
    }
  }
  if (const absl::Status spec = CheckVolumeSpec(args); !spec.ok()) {
    std::cerr << "isostream info: " << spec.message() << "\n";
    return 2;
  }
  auto prepared = Prepare(args);
  if (!prepared.ok()) {
    std::cerr << "isostream info: " << prepared.status().message() << "\n";
    return 1;
  }
  const Volume& v = *prepared->volume;
  const Hierarchy& h = *prepared->hierarchy;
  const int n = h.n();
  const int threads = args.threads > 0 ? args.threads : int(std::thread::hardware_concurrency());
  std::printf("volume        %s\n", v.name.c_str());
  std::printf("dims          %d x %d x %d  (%lld samples)\n", v.dims[0], v.dims[1], v.dims[2],
              (long long)v.voxel_count());
  std::printf("spacing       %g %g %g\n", v.spacing[0], v.spacing[1], v.spacing[2]);
  std::printf("origin        %g %g %g\n", v.origin[0], v.origin[1], v.origin[2]);
  if (!v.orientation.empty()) std::printf("orientation   %s\n", v.orientation.c_str());
  if (v.meters_per_unit > 0) std::printf("unit          %s\n", UnitText(v.meters_per_unit).c_str());
  // Every digit the samples hold: %g's six made 1e6 and 1e6 + 0.0625 one value.
  std::printf("value range   [%s, %s]\n", ShortestText(v.min_value).c_str(),
              ShortestText(v.max_value).c_str());
  std::printf("hierarchy     cube %d^3 (k = %d), %d bisection levels, %zu refinement vertices\n", n,
              h.k(), 3 * h.k(), h.point_count() - 8);
  if (h.stored_point_count() < h.point_count())
    std::printf(
        "stored        %d x %d x %d planes of the cube's (the rest stand-ins: %.1f%% of "
        "its points)\n",
        h.stored_dims()[0], h.stored_dims()[1], h.stored_dims()[2],
        100.0 * double(h.stored_point_count()) / double(h.point_count()));
  std::printf("eta (root)    %g  (error bound of the 6 initial tetrahedra, data units)\n",
              h.eta(n / 2, n / 2, n / 2));
  std::printf("memory        eta %.1f MiB (%.2f B/point), samples+eta store %.1f MiB\n",
              h.eta_bytes() / 1048576.0, double(h.eta_bytes()) / double(h.stored_point_count()),
              h.total_bytes() / 1048576.0);
  std::printf("load          %.3f s\n", prepared->load_s);
  std::printf("pad           %.3f s\n", prepared->pad_s);
  std::printf("hierarchy     %.3f s  (%d threads, %.0f M points/s; cache %s)\n",
              prepared->hierarchy_s, threads, h.stored_point_count() / prepared->hierarchy_s / 1e6,
              CacheOutcomeName(prepared->cache));
  if (!prepared->cache_note.empty())
    std::printf("cache         %s\n", prepared->cache_note.c_str());
  if (iso.empty()) {
    const std::string coarse = CoarseValuesNote(v.min_value, v.max_value, args.volume);
    if (!coarse.empty()) std::fprintf(stderr, "isostream info: note: %s\n", coarse.c_str());
    return 0;
  }
  NoteIsovaluesOutside("isostream info", counting.isovalues, prepared->volume->min_value,
                       prepared->volume->max_value, args.volume);
  return PrintCountsByEps(*prepared, counting, iso);
}

}  // namespace

CLI::App* AddInfoCommand(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand("info", "Load a volume, build its hierarchy, print facts");
  auto args = std::make_shared<VolumeArgs>();
  auto iso = std::make_shared<std::string>();
  AddVolumeOptions(cmd, args.get());
  cmd->add_option("--iso", *iso,
                  "isovalues, comma separated: also print the triangle count at each octave of "
                  "eps (one counting pass at full resolution)")
      ->check(GivenNumber());  // given but empty: an error, not "no table"
  cmd->callback([args, iso, exit_code] { *exit_code = RunInfo(*args, *iso); });
  return cmd;
}

}  // namespace isostream::cli
