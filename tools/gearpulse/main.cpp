// gearpulse: the offline tool (fit, replay, track) over logs and recordings.
#include <string>

#include <CLI/CLI.hpp>

#include "gearpulse_version.hpp"
#include "tools/gearpulse/commands.hpp"
#include "tools/gearpulse/run_app.hpp"

int main(int argc, char** argv) {
  CLI::App app{"gearpulse: learn gear scales and synthesize speed pulses, offline"};
  app.set_version_flag("--version", std::string("gearpulse ") + gearpulse::kVersion);
  app.require_subcommand(1);
  int status = 0;
  gearpulse::cli::add_fit(app, status);
  gearpulse::cli::add_replay(app, status);
  gearpulse::cli::add_track(app, status);
  return gearpulse::cli::run_app(app, argc, argv, status, "gearpulse");
}
