#include <cstdio>

#include "server/cli/commands.h"

int main(int argc, char** argv) {
  CLI::App app{"isostream: multiresolution transparent isosurfaces (Gerstner's method)"};
  app.require_subcommand(1);
  int exit_code = 0;
  isostream::cli::AddInfoCommand(app, &exit_code);
  isostream::cli::AddTetsCommand(app, &exit_code);
  isostream::cli::AddExtractCommand(app, &exit_code);
  isostream::cli::AddFetchCommand(app, &exit_code);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  return exit_code;
}
