#include "server/cli/cli_common.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <glm/geometric.hpp>
#include <limits>

#include "server/volume/volume_spec.h"
#include "shared/given_number.h"
#include "shared/number_list.h"

namespace isostream::cli {

void AddVolumeOptions(CLI::App* cmd, VolumeArgs* args) {
  cmd->add_option("--volume", args->volume,
                  "generator (cayley:N, buckyball:N, sphere:N, shells:N, noise:N[:SEED]), "
                  "a .vdb/.nii/.nii.gz file, or raw:PATH:NXxNYxNZ:TYPE[:le|be]")
      ->required();
  cmd->add_option("--threads", args->threads, "worker threads (0: all cores)")
      ->check(CLI::Range(0, 1024));
  cmd->add_option("--cache-dir", args->cache_dir, "hierarchy cache directory");
  cmd->add_flag("--no-cache", args->no_cache, "always rebuild the hierarchy, store nothing");
  // The hierarchy pads a volume to the cube of its longest side, at most 4097 (k = 12); it stores
  // at most 1025^3 of the cube's points (a thin volume its data's planes and stand-ins).
  cmd->add_option("--max-dim", args->max_dim, "largest accepted samples per axis (2..4097)")
      ->check(CLI::Range(2, 4097));
}

namespace {

VolumeLimits Limits(const VolumeArgs& args) {
  VolumeLimits limits;
  limits.max_dim = args.max_dim;
  return limits;
}

}  // namespace

absl::Status CheckVolumeSpec(const VolumeArgs& args) {
  return ParseVolumeSpec(args.volume, Limits(args)).status();
}

absl::StatusOr<PreparedVolume> Prepare(const VolumeArgs& args) {
  const VolumeLimits limits = Limits(args);
  HierarchyCacheOptions cache;
  if (!args.no_cache) cache.dir = args.cache_dir;
  HierarchyBuildOptions build;
  build.threads = args.threads;
  // Progress on stderr; BuildHierarchy reports only for builds over 16 M points.
  {
    auto last = std::make_shared<int>(-1);
    build.progress = [last](double f) {
      const int percent = int(100 * f);
      if (percent == *last) return;
      *last = percent;
      if (percent < 100)
        std::fprintf(stderr, "\rbuilding hierarchy: %3d%%", percent);
      else
        std::fprintf(stderr, "\r                         \r");
      std::fflush(stderr);
    };
  }
  return PrepareVolume(args.volume, limits, cache, build);
}

void AddViewOptions(CLI::App* cmd, ViewArgs* args) {
  cmd->add_option("--iso", args->iso, "isovalues, comma separated (at most 16)")->required();
  const CLI::Validator given_number = GivenNumber();
  auto* eps = cmd->add_option("--eps", args->eps, "error bound in data units (0: full resolution)")
                  ->check(given_number);
  auto* budget =
      cmd->add_option("--budget", args->budget, "triangle budget: find the smallest eps that fits")
          ->transform(GivenCount());
  eps->excludes(budget);
  auto* eye = cmd->add_option("--eye", args->eye, "perspective eye x,y,z (world units)");
  auto* dir = cmd->add_option("--view-dir", args->view_dir, "orthographic view direction x,y,z");
  eye->excludes(dir);
  args->eps_flag = eps;
  args->budget_flag = budget;
  args->eye_flag = eye;
  args->view_dir_flag = dir;
  cmd->add_option("--order", args->order, "back-to-front (default) or none")
      ->check(CLI::IsMember({"back-to-front", "none"}));
  cmd->add_option("--normals", args->normals, "smooth (default) or flat")
      ->check(CLI::IsMember({"smooth", "flat"}));
}

absl::StatusOr<std::vector<double>> ParseNumbers(const std::string& text, const char* what) {
  return ParseNumberList(text, what);
}

absl::StatusOr<std::vector<float>> ParseIsovalues(const std::string& text) {
  ISOSTREAM_ASSIGN_OR_RETURN(std::vector<double> iso, ParseNumbers(text, "--iso"));
  std::vector<float> out;
  for (double v : iso) {
    if (std::isfinite(v) && std::fabs(v) > double(std::numeric_limits<float>::max())) {
      char shown[32];
      std::snprintf(shown, sizeof(shown), "%g", v);
      return absl::InvalidArgumentError(std::string("--iso ") + shown +
                                        " is outside the single-precision range of the samples");
    }
    out.push_back(float(v));
  }
  return out;
}

absl::Status CheckViewArgs(const ViewArgs& args) {
  const auto early = MakeRequest(args, Volume{});
  return early.ok() ? ValidateRequest(*early) : early.status();
}

absl::StatusOr<ExtractRequest> MakeRequest(const ViewArgs& args, const Volume& volume) {
  ExtractRequest r;
  ISOSTREAM_ASSIGN_OR_RETURN(r.isovalues, ParseIsovalues(args.iso));
  const auto given = [](const CLI::Option* flag) { return flag != nullptr && flag->count() > 0; };
  if (given(args.budget_flag)) {
    if (args.budget <= 0)
      return absl::InvalidArgumentError("--budget must be a positive triangle count");
    r.budget = args.budget;
  } else if (!given(args.eps_flag)) {
    return absl::InvalidArgumentError("give --eps E (>= 0, data units) or --budget N");
  } else if (args.eps < 0 || !std::isfinite(args.eps)) {
    return absl::InvalidArgumentError("--eps must be a finite number >= 0 (data units)");
  } else {
    r.eps = args.eps;
  }
  if (given(args.view_dir_flag)) {
    ISOSTREAM_ASSIGN_OR_RETURN(std::vector<double> d, ParseNumbers(args.view_dir, "--view-dir"));
    if (d.size() != 3) return absl::InvalidArgumentError("--view-dir needs x,y,z");
    r.view.orthographic = true;
    r.view.direction = {d[0], d[1], d[2]};
  } else if (given(args.eye_flag)) {
    ISOSTREAM_ASSIGN_OR_RETURN(std::vector<double> e, ParseNumbers(args.eye, "--eye"));
    if (e.size() != 3) return absl::InvalidArgumentError("--eye needs x,y,z");
    r.view.eye = {e[0], e[1], e[2]};
  } else {
    glm::dvec3 lo, hi;
    for (int a = 0; a < 3; ++a) {
      lo[a] = volume.origin[a];
      hi[a] = volume.origin[a] + volume.spacing[a] * (volume.dims[a] - 1);
    }
    const glm::dvec3 centre = 0.5 * (lo + hi);
    r.view.eye = centre + 1.6 * glm::length(hi - lo) * glm::normalize(glm::dvec3(0.8, 0.6, 1.0));
  }
  r.order = args.order == "none" ? DrawOrder::kNone : DrawOrder::kBackToFront;
  r.normals = args.normals == "flat" ? NormalMode::kFlat : NormalMode::kSmooth;
  return r;
}

std::string UnitText(double meters_per_unit) {
  const std::string meters = ShortestText(meters_per_unit) + " m";
  if (meters_per_unit == 1) return meters;
  if (meters_per_unit == 1e-3) return "mm (" + meters + ")";
  if (meters_per_unit == 1e-6) return "µm (" + meters + ")";
  return meters;
}

}  // namespace isostream::cli
