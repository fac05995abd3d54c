// The flags of the subcommands that talk to a running isostreamd (fetch, volumes, stats): where
// it is, how to authenticate, and how long to wait.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <string>

#include "client/net/session_client.h"
#include "shared/status.h"

namespace isostream::cli {

struct ConnectionArgs {
  std::string server = "127.0.0.1:7878";
  std::string token;
  std::string tls_ca;
  int timeout_s = 60;
  // What --timeout-s bounds, for the message of a call past it (ClientOptions).
  std::string timeout_means = "--timeout-s bounds each call";
};

// --server, --token, --tls-ca and --timeout-s; `timeout_means` is --timeout-s's help.
void AddConnectionOptions(CLI::App* cmd, ConnectionArgs* args, const std::string& timeout_means);

// Sets `options`' address, token, timeout and TLS roots from `args` (its other fields are the
// caller's) and connects. InvalidArgument for a --tls-ca file that holds no certificate or an
// address or token gRPC cannot take: an argument's fault (exit 2, ExitCodeFor).
absl::StatusOr<std::unique_ptr<net::Client>> ConnectTo(const ConnectionArgs& args,
                                                       net::ClientOptions* options);

// 2 for an argument's fault (InvalidArgument), else 1.
int ExitCodeFor(const absl::Status& status);

}  // namespace isostream::cli
