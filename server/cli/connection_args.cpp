#include "server/cli/connection_args.h"

#include <chrono>
#include <utility>

namespace isostream::cli {

void AddConnectionOptions(CLI::App* cmd, ConnectionArgs* args, const std::string& timeout_means) {
  cmd->add_option("--server", args->server, "isostreamd address HOST:PORT")->capture_default_str();
  cmd->add_option("--token", args->token, "bearer token, if the daemon requires one");
  cmd->add_option("--tls-ca", args->tls_ca, "PEM root certificates: connect with TLS");
  cmd->add_option("--timeout-s", args->timeout_s, timeout_means)->check(CLI::Range(0, 86400));
}

absl::StatusOr<std::unique_ptr<net::Client>> ConnectTo(const ConnectionArgs& args,
                                                       net::ClientOptions* options) {
  options->address = args.server;
  options->token = args.token;
  options->call_timeout = std::chrono::seconds(args.timeout_s);
  options->call_timeout_means = args.timeout_means;
  if (!args.tls_ca.empty()) {
    auto pem = net::ReadTlsCa(args.tls_ca);
    if (!pem.ok()) return pem.status();
    options->tls_ca_pem = std::move(*pem);
  }
  return net::Client::Connect(*options);
}

int ExitCodeFor(const absl::Status& status) {
  return status.code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
}

}  // namespace isostream::cli
