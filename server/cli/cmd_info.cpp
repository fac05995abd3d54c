// `isostream info --volume SPEC`: load a volume, build (or load) its hierarchy, print facts.
#include <chrono>
#include <cstdio>
#include <iostream>
#include <thread>

#include "server/cli/commands.h"
#include "server/hierarchy/hierarchy_cache.h"
#include "server/volume/load.h"
#include "server/volume/padding.h"

namespace isostream::cli {
namespace {

struct InfoArgs {
  std::string volume;
  std::string cache_dir = DefaultCacheDir();
  bool no_cache = false;
  int threads = 0;
  int max_dim = VolumeLimits{}.max_dim;
};

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

int RunInfo(const InfoArgs& args) {
  VolumeLimits limits;
  limits.max_dim = args.max_dim;
  auto t0 = std::chrono::steady_clock::now();
  auto volume = LoadVolume(args.volume, limits);
  if (!volume.ok()) {
    std::cerr << "isostream info: " << volume.status().message() << "\n";
    return 1;
  }
  const double load_s = Seconds(t0);
  const Volume& v = **volume;
  t0 = std::chrono::steady_clock::now();
  auto padded = PadToHierarchyDomain(v);
  if (!padded.ok()) {
    std::cerr << "isostream info: " << padded.status().message() << "\n";
    return 1;
  }
  const double pad_s = Seconds(t0);
  const int k = padded->k, n = padded->n;

  HierarchyBuildOptions build;
  build.threads = args.threads;
  const bool big = int64_t{n} * n * n > (int64_t{1} << 24);
  if (big) {
    build.progress = [](double f) {
      std::fprintf(stderr, "\rbuilding hierarchy: %3.0f%%", 100 * f);
      std::fflush(stderr);
    };
  }
  HierarchyCacheOptions cache;
  if (!args.no_cache) cache.dir = args.cache_dir;
  CacheOutcome outcome;
  std::string why;
  t0 = std::chrono::steady_clock::now();
  auto hier = LoadOrBuildHierarchy(std::move(*padded), cache, build, &outcome, &why);
  const double build_s = Seconds(t0);
  if (big && outcome != CacheOutcome::kHit) std::fprintf(stderr, "\n");
  if (!hier.ok()) {
    std::cerr << "isostream info: " << hier.status().message() << "\n";
    return 1;
  }
  const Hierarchy& h = **hier;
  const double voxels = double(v.voxel_count());
  const int threads = args.threads > 0 ? args.threads : int(std::thread::hardware_concurrency());
  std::printf("volume        %s\n", v.name.c_str());
  std::printf("dims          %d x %d x %d  (%.0f samples)\n", v.dims[0], v.dims[1], v.dims[2],
              voxels);
  std::printf("spacing       %g %g %g\n", v.spacing[0], v.spacing[1], v.spacing[2]);
  std::printf("origin        %g %g %g\n", v.origin[0], v.origin[1], v.origin[2]);
  std::printf("value range   [%g, %g]\n", v.min_value, v.max_value);
  std::printf("hierarchy     cube %d^3 (k = %d), %d bisection levels, %zu refinement vertices\n", n,
              k, 3 * k, h.point_count() - 8);
  std::printf("eta (root)    %g  (error bound of the 6 initial tetrahedra, data units)\n",
              h.eta(n / 2, n / 2, n / 2));
  std::printf("memory        eta %.1f MiB (%.2f B/voxel of the padded cube), samples %.1f MiB\n",
              h.eta_bytes() / 1048576.0, double(h.eta_bytes()) / h.point_count(),
              h.point_count() * 4 / 1048576.0);
  std::printf("load          %.3f s\n", load_s);
  std::printf("pad           %.3f s\n", pad_s);
  std::printf("build         %.3f s  (%d threads, %.0f M points/s; cache %s)\n", build_s, threads,
              h.point_count() / build_s / 1e6, CacheOutcomeName(outcome));
  if (!why.empty()) std::printf("cache         %s\n", why.c_str());
  return 0;
}

}  // namespace

CLI::App* AddInfoCommand(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand("info", "Load a volume, build its hierarchy, print facts");
  auto args = std::make_shared<InfoArgs>();
  cmd->add_option("--volume", args->volume,
                  "generator (cayley:N, buckyball:N, sphere:N, shells:N, noise:N[:SEED]) or file")
      ->required();
  cmd->add_option("--threads", args->threads, "worker threads (0: all cores)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--cache-dir", args->cache_dir, "hierarchy cache directory");
  cmd->add_flag("--no-cache", args->no_cache, "always rebuild, store nothing");
  cmd->add_option("--max-dim", args->max_dim, "largest accepted samples per axis")
      ->check(CLI::Range(2, 4097));
  cmd->callback([args, exit_code] { *exit_code = RunInfo(*args); });
  return cmd;
}

}  // namespace isostream::cli
