#include <cstdio>
#include <exception>
#include <new>

#include "client/net/session_client.h"
#include "server/cli/commands.h"
#include "shared/file_io.h"
#include "shared/malloc_tuning.h"

int main(int argc, char** argv) {
  // fetch decodes chunk after chunk, extract fills subtree buffers: both reuse freed memory.
  isostream::KeepFreedMemoryForReuse();
  isostream::net::QuietGrpcLogs();  // fetch, volumes and stats explain their failures
  CLI::App app{"isostream: multiresolution transparent isosurfaces (Gerstner's method)"};
  app.require_subcommand(1);
  int exit_code = 0;
  isostream::cli::AddInfoCommand(app, &exit_code);
  isostream::cli::AddTetsCommand(app, &exit_code);
  isostream::cli::AddExtractCommand(app, &exit_code);
  isostream::cli::AddFetchCommand(app, &exit_code);
  isostream::cli::AddVolumesCommand(app, &exit_code);
  isostream::cli::AddStatsCommand(app, &exit_code);
  // CLI11 says only "A subcommand is required" for a misspelt one.
  if (argc > 1 && argv[1][0] != '-') {
    try {
      app.get_subcommand(argv[1]);
    } catch (const CLI::OptionNotFound&) {
      std::fprintf(
          stderr,
          "isostream: unknown command '%s' (info, tets, extract, fetch, volumes or stats)\n",
          argv[1]);
      return 2;
    }
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Usage errors exit 2, as the commands' own argument errors do (CLI11's codes are 100+);
    // --help exits 0 if the help could be written.
    if (app.exit(e) != 0) return 2;
    return isostream::FlushStandardOutput("isostream") ? 0 : 1;
  } catch (const std::bad_alloc&) {
    // The commands report errors as statuses; these are the last line, so no input ends in
    // std::terminate.
    std::fprintf(stderr, "error: out of memory\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  // What a command printed (the tets table, the info report, --stats) is its result too.
  if (!isostream::FlushStandardOutput("isostream") && exit_code == 0) return 1;
  return exit_code;
}
