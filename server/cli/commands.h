// The `isostream` command line: one file per subcommand, each registering itself here.
#pragma once

#include <CLI/CLI.hpp>

namespace isostream::cli {

// Each returns the subcommand; its callback sets *exit_code.
CLI::App* AddInfoCommand(CLI::App& app, int* exit_code);
CLI::App* AddTetsCommand(CLI::App& app, int* exit_code);
CLI::App* AddExtractCommand(CLI::App& app, int* exit_code);
CLI::App* AddFetchCommand(CLI::App& app, int* exit_code);
CLI::App* AddVolumesCommand(CLI::App& app, int* exit_code);
CLI::App* AddStatsCommand(CLI::App& app, int* exit_code);

}  // namespace isostream::cli
