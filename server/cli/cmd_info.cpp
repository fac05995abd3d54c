// `isostream info --volume SPEC`: load a volume, build (or load) its hierarchy, print facts.
#include <cstdio>
#include <iostream>
#include <thread>

#include "server/cli/cli_common.h"
#include "server/cli/commands.h"

namespace isostream::cli {
namespace {

int RunInfo(const VolumeArgs& args) {
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
  std::printf("value range   [%g, %g]\n", v.min_value, v.max_value);
  std::printf("hierarchy     cube %d^3 (k = %d), %d bisection levels, %zu refinement vertices\n", n,
              h.k(), 3 * h.k(), h.point_count() - 8);
  std::printf("eta (root)    %g  (error bound of the 6 initial tetrahedra, data units)\n",
              h.eta(n / 2, n / 2, n / 2));
  std::printf("memory        eta %.1f MiB (%.2f B/point), samples+eta store %.1f MiB\n",
              h.eta_bytes() / 1048576.0, double(h.eta_bytes()) / double(h.point_count()),
              h.total_bytes() / 1048576.0);
  std::printf("load          %.3f s\n", prepared->load_s);
  std::printf("pad           %.3f s\n", prepared->pad_s);
  std::printf("hierarchy     %.3f s  (%d threads, %.0f M points/s; cache %s)\n",
              prepared->hierarchy_s, threads, h.point_count() / prepared->hierarchy_s / 1e6,
              CacheOutcomeName(prepared->cache));
  if (!prepared->cache_note.empty())
    std::printf("cache         %s\n", prepared->cache_note.c_str());
  return 0;
}

}  // namespace

CLI::App* AddInfoCommand(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand("info", "Load a volume, build its hierarchy, print facts");
  auto args = std::make_shared<VolumeArgs>();
  AddVolumeOptions(cmd, args.get());
  cmd->callback([args, exit_code] { *exit_code = RunInfo(*args); });
  return cmd;
}

}  // namespace isostream::cli
