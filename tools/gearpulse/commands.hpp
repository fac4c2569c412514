#pragma once
// Subcommands of the offline tool (tools/gearpulse/) and of gearpulse-devtools (tools/devtools/); each
// lives in its own cmd_*.cpp and registers itself on the app.
#include <stdexcept>
#include <string>

namespace CLI {
class App;
}

namespace gearpulse::cli {

// Thrown for bad input or options; run_app() prints "NAME: <what>" on one line and exits 2.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Each adds its subcommand; the callback stores its exit status in `status`.
void add_fit(CLI::App& app, int& status);
void add_replay(CLI::App& app, int& status);
void add_track(CLI::App& app, int& status);
// gearpulse-devtools only.
void add_simulate(CLI::App& app, int& status);
void add_feed(CLI::App& app, int& status);

}  // namespace gearpulse::cli
