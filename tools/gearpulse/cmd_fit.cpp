// Placeholder until the 'fit' subcommand lands.
#include <CLI/CLI.hpp>

#include "tools/gearpulse/commands.hpp"

namespace gearpulse::cli {

void add_fit(CLI::App& app, int& status) {
  app.add_subcommand("fit", "(not built yet)")->callback([&status] {
    throw UsageError("'fit' is not implemented in this build");
    status = 2;
  });
}

}  // namespace gearpulse::cli
