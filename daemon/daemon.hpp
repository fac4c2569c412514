#pragma once
// gearpulsed as a whole: persistence, the pipeline, the retrainer, the control socket, systemd
// notification and signals. main() parses the command line and hands over here.
#include <memory>
#include <string>

#include "daemon/config.hpp"
#include "daemon/retrainer.hpp"

namespace gearpulse::daemon {

// Applies the configured log level to the default spdlog logger; returns false for an unknown name.
bool apply_log_level(const std::string& level);

class Daemon {
 public:
  // `config_path` is re-read on SIGHUP. `fitter` learns a model from training pairs.
  Daemon(Config config, std::string config_path, Retrainer::Fitter fitter);
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Runs until SIGTERM or SIGINT; returns the process exit status.
  int run();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace gearpulse::daemon
