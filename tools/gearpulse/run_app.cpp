#include "tools/gearpulse/run_app.hpp"

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

#include <CLI/CLI.hpp>

#include "tools/gearpulse/commands.hpp"

namespace gearpulse::cli {

int run_app(CLI::App& app, int argc, char** argv, const int& status, const char* name) {
  // Output into a pipe whose reader has gone is a write that fails (said below, exit 2), not a death by
  // SIGPIPE that a script reads as 141.
  std::signal(SIGPIPE, SIG_IGN);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::Success& e) {
    return app.exit(e);
  } catch (const CLI::RequiredError& e) {
    // An unknown command reads to CLI11 as none at all: name it (a known one missing an option is
    // reported as CLI11 words it).
    std::string known;
    bool is_known = false;
    for (const CLI::App* sub : app.get_subcommands({})) {
      known += (known.empty() ? "" : ", ") + sub->get_name();
      is_known = is_known || (argc > 1 && sub->get_name() == argv[1]);
    }
    if (argc == 1) {
      std::fprintf(stderr, "%s: a command is required (commands: %s; %s --help says what each does)\n", name,
                   known.c_str(), name);
    } else if (argc > 1 && argv[1][0] != '-' && !is_known) {
      std::fprintf(stderr, "%s: unknown command '%s' (commands: %s)\n", name, argv[1], known.c_str());
    } else {
      std::fprintf(stderr, "%s: %s\n", name, e.what());
    }
    return 2;
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "%s: %s\n", name, e.what());
    return 2;
  } catch (const UsageError& e) {
    std::fprintf(stderr, "%s: %s\n", name, e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s\n", name, e.what());
    return 2;
  }
  // Output that did not reach stdout (a full disk, /dev/full) is an error: a truncated CSV must not look
  // like a finished one.
  errno = 0;
  if (std::fflush(stdout) != 0 || std::ferror(stdout)) {
    std::fprintf(stderr, "%s: cannot write the output to stdout%s%s\n", name, errno ? ": " : "",
                 errno ? std::strerror(errno) : "");
    return 2;
  }
  return status;
}

}  // namespace gearpulse::cli
