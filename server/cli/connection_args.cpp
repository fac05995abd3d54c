#include "server/cli/connection_args.h"

namespace isostream::cli {

void AddConnectionOptions(CLI::App* cmd, ConnectionArgs* args, const std::string& timeout_means) {
  cmd->add_option("--server", args->server, "isostreamd address HOST:PORT")->capture_default_str();
  cmd->add_option("--token", args->token, "bearer token, if the daemon requires one");
  cmd->add_option("--tls-ca", args->tls_ca, "PEM root certificates: connect with TLS");
  cmd->add_option("--timeout-s", args->timeout_s, timeout_means)->check(CLI::Range(0, 86400));
}

int ExitCodeFor(const absl::Status& status) {
  return status.code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
}

}  // namespace isostream::cli
