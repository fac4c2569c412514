// Placeholder until the 'track' subcommand lands.
#include <CLI/CLI.hpp>

#include "tools/gearpulse/commands.hpp"

namespace gearpulse::cli {

void add_track(CLI::App& app, int& status) {
  app.add_subcommand("track", "(not built yet)")->callback([&status] {
    throw UsageError("'track' is not implemented in this build");
    status = 2;
  });
}

}  // namespace gearpulse::cli
