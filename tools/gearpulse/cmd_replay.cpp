// Placeholder until the 'replay' subcommand lands.
#include <CLI/CLI.hpp>

#include "tools/gearpulse/commands.hpp"

namespace gearpulse::cli {

void add_replay(CLI::App& app, int& status) {
  app.add_subcommand("replay", "(not built yet)")->callback([&status] {
    throw UsageError("'replay' is not implemented in this build");
    status = 2;
  });
}

}  // namespace gearpulse::cli
