#pragma once
// Parses the command line of a subcommand tool and runs the chosen command, with one error handling for
// every such tool: a one-line message "NAME: ..." on stderr and exit 2 for bad usage or failure.
namespace CLI {
class App;
}

namespace gearpulse::cli {

// `status` is where the command's callback stores its exit status; returned on success.
int run_app(CLI::App& app, int argc, char** argv, const int& status, const char* name);

}  // namespace gearpulse::cli
