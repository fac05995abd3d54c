// The flags of the subcommands that talk to a running isostreamd (fetch, volumes, stats): where
// it is, how to authenticate, and how long to wait.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "client/net/session_client.h"
#include "shared/status.h"

namespace isostream::cli {

// net::ConnectWith connects by them.
using ConnectionArgs = net::ConnectionFlags;

// --server, --token, --tls-ca and --timeout-s; `timeout_means` is --timeout-s's help.
void AddConnectionOptions(CLI::App* cmd, ConnectionArgs* args, const std::string& timeout_means);

// 2 for an argument's fault (InvalidArgument), else 1.
int ExitCodeFor(const absl::Status& status);

}  // namespace isostream::cli
