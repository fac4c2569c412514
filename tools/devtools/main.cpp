// gearpulse-devtools: simulated drives and a paced audio feeder for tests, benches and the demo. Built with
// the tree, not installed.
#include <string>

#include <CLI/CLI.hpp>

#include "gearpulse_version.hpp"
#include "tools/gearpulse/commands.hpp"
#include "tools/gearpulse/run_app.hpp"

int main(int argc, char** argv) {
  CLI::App app{"gearpulse-devtools: simulated drives and a paced audio feeder (development only)"};
  app.set_version_flag("--version", std::string("gearpulse-devtools ") + gearpulse::kVersion);
  app.require_subcommand(1);
  int status = 0;
  gearpulse::cli::add_simulate(app, status);
  gearpulse::cli::add_feed(app, status);
  return gearpulse::cli::run_app(app, argc, argv, status, "gearpulse-devtools");
}
