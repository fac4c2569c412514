// Placeholder until the 'simulate' subcommand lands.
#include <CLI/CLI.hpp>

#include "tools/gearpulse/commands.hpp"

namespace gearpulse::cli {

void add_simulate(CLI::App& app, int& status) {
  app.add_subcommand("simulate", "(not built yet)")->callback([&status] {
    throw UsageError("'simulate' is not implemented in this build");
    status = 2;
  });
}

}  // namespace gearpulse::cli
