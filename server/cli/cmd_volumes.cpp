// `isostream volumes`: what a running isostreamd serves (its catalogue, or the generators it
// accepts), and with --info each volume's facts, as clients see them.
#include <cstdio>
#include <iostream>

#include "client/net/session_client.h"
#include "server/cli/cli_common.h"
#include "server/cli/commands.h"
#include "server/cli/connection_args.h"
#include "shared/number_list.h"

namespace isostream::cli {
namespace {

namespace pb = ::isostream::v1;

struct VolumesArgs {
  ConnectionArgs connection;
  bool info = false;
};

std::string Triple(const pb::Vec3& v) {
  return ShortestText(v.x()) + ", " + ShortestText(v.y()) + ", " + ShortestText(v.z());
}

void PrintInfo(const pb::VolumeInfo& v) {
  std::printf("  dims            ");
  for (int a = 0; a < v.dims_size(); ++a) std::printf(a ? " x %d" : "%d", v.dims(a));
  std::printf("\n  spacing         %s\n", Triple(v.spacing()).c_str());
  std::printf("  origin          %s\n", Triple(v.origin()).c_str());
  std::printf("  value range     [%s, %s]\n", ShortestText(v.min_value()).c_str(),
              ShortestText(v.max_value()).c_str());
  std::printf("  position error  %s%s\n", ShortestText(v.position_error()).c_str(),
              v.position_error() == 0 ? " (unquantized positions)" : "");
  if (!v.orientation().empty()) std::printf("  orientation     %s\n", v.orientation().c_str());
  if (v.meters_per_unit() > 0)
    std::printf("  unit            %s\n", UnitText(v.meters_per_unit()).c_str());
}

int RunVolumes(const VolumesArgs& args) {
  auto fail = [](const std::string& m, int code) {
    std::cerr << "isostream volumes: " << m << "\n";
    return code;
  };
  net::ClientOptions options;
  auto client = net::ConnectWith(args.connection, &options);
  if (!client.ok())
    return fail(std::string(client.status().message()), ExitCodeFor(client.status()));
  auto list = (*client)->ListVolumes();
  if (!list.ok()) return fail(net::ExplainCallError(list.status(), options), 1);
  if (list->generators_allowed())
    std::printf(
        "no catalogue: generator specs (cayley:N, buckyball:N, sphere:N, shells:N, "
        "noise:N[:SEED]) with N up to %d\n",
        list->max_generator_dim());
  int failed = 0;
  for (const std::string& name : list->names()) {
    std::printf("%s\n", name.c_str());
    if (!args.info) continue;
    // One bin: the facts, not the histogram (which reads every sample).
    auto info = (*client)->GetVolumeInfo(name, 1);
    if (info.ok()) {
      PrintInfo(*info);
    } else {
      std::printf("  not served: %s\n", net::ExplainCallError(info.status(), options).c_str());
      ++failed;
    }
  }
  return failed == 0 ? 0 : 1;
}

}  // namespace

CLI::App* AddVolumesCommand(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand(
      "volumes", "List what a running isostreamd serves (--info: each volume's facts)");
  auto args = std::make_shared<VolumesArgs>();
  AddConnectionOptions(cmd, &args->connection,
                       "each call fails after this many seconds, connecting included (default "
                       "60; 0: wait forever)");
  cmd->add_flag("--info", args->info,
                "each volume's dims, spacing, origin, values and position error (prepares the "
                "volumes not prepared yet; exit 1 if one cannot be)");
  cmd->callback([args, exit_code] { *exit_code = RunVolumes(*args); });
  return cmd;
}

}  // namespace isostream::cli
