// gearpulsed: learns gear scales from engine ripple and GPS, emits a synthetic speed-pulse train.
#include <malloc.h>
#include <sys/resource.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "daemon/config.hpp"
#include "daemon/daemon.hpp"
#include "daemon/fitter.hpp"
#include "daemon/log_queue.hpp"
#include "gearpulse_version.hpp"

namespace {

constexpr const char* kDefaultConfig = "/etc/gearpulse/gearpulse.toml";

void usage(std::FILE* to) {
  std::fprintf(to,
               "usage: gearpulsed [--config FILE] [--check-config] | --version | --help\n"
               "  -c, --config FILE  TOML configuration (also --config=FILE; default %s)\n"
               "  --check-config     validate the configuration and exit (0 = valid, 2 = invalid)\n"
               "  --version          print the version and exit\n"
               "  -h, --help         print this help and exit\n",
               kDefaultConfig);
}

// Descriptors: the soft limit raised to the hard one, as systemd advises a service that needs more than
// the 1024 it starts every service with. At the soft limit the control server can no longer accept, so
// not even the slot kept for the daemon's own user can be given (control.max_clients goes up to 1024,
// beside the daemon's own descriptors: the audio, gpsd, the output, the state files, the journal).
void raise_descriptor_limit(std::int64_t max_clients) {
  constexpr rlim_t kOwn = 64;  // the daemon's own descriptors, with room to spare
  rlimit lim{};
  if (::getrlimit(RLIMIT_NOFILE, &lim) != 0) return;
  if (lim.rlim_cur < lim.rlim_max) {
    const rlim_t was = lim.rlim_cur;
    lim.rlim_cur = lim.rlim_max;
    if (::setrlimit(RLIMIT_NOFILE, &lim) != 0) lim.rlim_cur = was;
  }
  const auto needed = static_cast<rlim_t>(max_clients) + kOwn;
  if (lim.rlim_cur != RLIM_INFINITY && lim.rlim_cur < needed)
    spdlog::warn(
        "control: control.max_clients ({}) connections need about {} file descriptors and RLIMIT_NOFILE "
        "allows {}: once they are used up no new connection is served, the daemon's own user's neither; "
        "lower control.max_clients or raise the limit (LimitNOFILE= in the unit)",
        max_clients, needed, static_cast<std::uint64_t>(lim.rlim_cur));
}

}  // namespace

int main(int argc, char** argv) {
  // Two malloc arenas, not glibc's eight per core: each thread that allocates would otherwise reserve an
  // arena's 64 MB of address space. With [audio] realtime = true the memory is locked (mlockall with
  // MCL_FUTURE), and every later mapping then counts against RLIMIT_MEMLOCK (512M in the systemd unit),
  // past which mappings (a retrain's copy of the store, its fit thread) are refused. The e2e drive's
  // address space peaked at 395 MB so, at 188 MB with two. The real-time threads do not allocate, so they
  // never wait on an arena's lock.
  (void)::mallopt(M_ARENA_MAX, 2);
  std::string config_path = kDefaultConfig;
  bool check_only = false;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--config" || arg == "-c") {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "gearpulsed: --config needs a file\n");
        return 2;
      }
      config_path = argv[++i];
    } else if (arg.starts_with("--config=")) {
      config_path = std::string(arg.substr(9));
    } else if (arg == "--check-config") {
      check_only = true;
    } else if (arg == "--version") {
      std::printf("gearpulsed %s\n", gearpulse::kVersion);
      return 0;
    } else if (arg == "--help" || arg == "-h") {
      usage(stdout);
      return 0;
    } else {
      std::fprintf(stderr, "gearpulsed: unknown argument '%s'\n", argv[i]);
      usage(stderr);
      return 2;
    }
  }

  gearpulse::daemon::Config config;
  try {
    config = gearpulse::daemon::load_config(config_path);
  } catch (const gearpulse::daemon::ConfigError& e) {
    std::fprintf(stderr, "gearpulsed: %s\n", e.what());
    return 2;
  }
  if (check_only) {
    std::printf("%s: configuration OK\n", config_path.c_str());
    return 0;
  }

  // journald stamps every line itself; keep level and text only. Lines reach stderr through a queue of
  // their own, so no thread of the daemon waits for the journal (LogQueue).
  const gearpulse::daemon::LogQueue log("gearpulsed",
                                        std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
  spdlog::default_logger()->set_pattern("%^%l%$: %v");
  gearpulse::daemon::apply_log_level(config.log.level);
  spdlog::info("gearpulsed starting with {}", config_path);
  raise_descriptor_limit(config.control.max_clients);

  try {
    gearpulse::daemon::Daemon daemon(std::move(config), config_path,
                                     gearpulse::daemon::make_estimator_fitter());
    return daemon.run();
  } catch (const std::exception& e) {
    spdlog::critical("fatal: {}", e.what());
    return 1;
  }
}
