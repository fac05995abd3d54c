// `isostream stats`: a running isostreamd's counters (sessions, frames, bytes, retained frames),
// for an operator or a monitoring script.
#include <cstdio>
#include <iostream>

#include "client/net/session_client.h"
#include "server/cli/commands.h"
#include "server/cli/connection_args.h"

namespace isostream::cli {
namespace {

int RunStats(const ConnectionArgs& args) {
  auto fail = [](const std::string& m, int code) {
    std::cerr << "isostream stats: " << m << "\n";
    return code;
  };
  net::ClientOptions options;
  auto client = net::ConnectWith(args, &options);
  if (!client.ok())
    return fail(std::string(client.status().message()), ExitCodeFor(client.status()));
  auto stats = (*client)->GetServerStats();
  if (!stats.ok()) return fail(net::ExplainCallError(stats.status(), options), 1);
  // Every field by its proto name, one per line: as the wire contract documents them, and easy
  // for a script to pick out.
  const auto* descriptor = stats->GetDescriptor();
  const auto* reflection = stats->GetReflection();
  for (int i = 0; i < descriptor->field_count(); ++i) {
    const auto* field = descriptor->field(i);
    if (field->cpp_type() == google::protobuf::FieldDescriptor::CPPTYPE_BOOL)
      std::printf("%-22s %s\n", field->name().c_str(),
                  reflection->GetBool(*stats, field) ? "true" : "false");
    else if (field->cpp_type() == google::protobuf::FieldDescriptor::CPPTYPE_INT64)
      std::printf("%-22s %lld\n", field->name().c_str(),
                  (long long)reflection->GetInt64(*stats, field));
  }
  return 0;
}

}  // namespace

CLI::App* AddStatsCommand(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand("stats", "Print a running isostreamd's counters");
  auto args = std::make_shared<ConnectionArgs>();
  AddConnectionOptions(cmd, args.get(),
                       "the call fails after this many seconds, connecting included (default 60; "
                       "0: wait forever)");
  cmd->callback([args, exit_code] { *exit_code = RunStats(*args); });
  return cmd;
}

}  // namespace isostream::cli
