#include "daemon/daemon.hpp"

#include <poll.h>
#include <signal.h>
#include <sys/signalfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <mutex>
#include <optional>
#include <vector>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "daemon/change_reporter.hpp"
#include "daemon/control_handler.hpp"
#include "daemon/control_server.hpp"
#include "daemon/model_store.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/state_directory.hpp"
#include "daemon/state_saver.hpp"
#include "daemon/systemd_notify.hpp"
#include "daemon/training_store.hpp"
#include "daemon/watchdog.hpp"
#include "drivers/audio_front_end.hpp"
#include "drivers/unique_fd.hpp"

namespace gearpulse::daemon {
namespace {

using Clock = std::chrono::steady_clock;

// Between saves of the training store the new pairs are journaled this often: a power cut (a car PC
// without a shutdown controller loses power with the ignition) costs at most this much learning, for a
// few hundred bytes and one sync per interval.
constexpr std::chrono::seconds kJournalInterval{10};

// A write of the state directory that has run this long is said in the log and in status: as long as a
// pipeline thread may go without a heartbeat before it counts as hung (watchdog.hpp). The write goes on
// on its own thread; the pulses and the watchdog do not wait for it.
constexpr std::chrono::nanoseconds kSlowWrite{kStallNs};

Retrainer::Settings retrain_settings(const ModelConfig& m) {
  return {std::chrono::duration<double>(m.retrain_interval),
          m.min_new_samples,
          m.replace_min_samples,
          {m.learn_cluster_pairs, m.learn_first_refit, m.learn_young_time}};
}

}  // namespace

bool apply_log_level(const std::string& level) {
  const auto parsed = spdlog::level::from_str(level);
  if (parsed == spdlog::level::off && level != "off") return false;
  spdlog::set_level(parsed);
  show_alsa_library_errors(parsed == spdlog::level::trace);
  return true;
}

struct Daemon::Impl {
  Impl(Config c, std::string path, Retrainer::Fitter fitter)
      : config(std::move(c)),
        config_path(std::move(path)),
        store(config.model.store_hours * 3600.0, config.model.max_samples),
        state(config.model.state_dir, model, store, config.model.max_samples),
        saver({.unsaved = [this] { return store.unsaved(); },
               .save = [this] { return state.save_store("periodic"); },
               .journal = [this] { state.journal_store(); }},
              StateSaver::Seconds(config.model.save_interval), kJournalInterval),
        retrainer(store, model, state.model_path(), std::move(fitter), retrain_settings(config.model)),
        changes(config) {}

  Config config;
  std::string config_path;
  // Members are destroyed in reverse order: the state directory's lock outlives the retrainer and the
  // pipeline (which may still save into it), and the control server goes first (its thread reads all of
  // these), also when run() leaves by an exception before its orderly stop.
  ModelHolder model;
  TrainingStore store;
  StateDirectory state;
  StateSaver saver;  // stopped before the state directory goes
  Retrainer retrainer;
  std::optional<Pipeline> pipeline;
  Clock::time_point started = Clock::now();
  ChangeReporter changes;

  mutable std::mutex reload_mutex;
  std::string reload_error;                  // the last SIGHUP's file was refused ("" = it was taken)
  std::vector<std::string> restart_pending;  // changed by the last reload, waiting for a restart
  void reload();
  [[nodiscard]] std::vector<std::string> problems() const;
  control::StatusReply status();
  std::string status_line();
  std::optional<ControlServer> control;  // last: destroyed first (above)
};

void Daemon::Impl::reload() {
  spdlog::info("reload: re-reading {}", config_path);
  Config next;
  try {
    next = load_config(config_path);
  } catch (const ConfigError& e) {
    // Recorded before it is said: whoever reads the log line and then asks for status sees the refusal.
    {
      std::lock_guard lock(reload_mutex);
      reload_error = e.what();
    }
    spdlog::error("reload: {}; keeping the running configuration (a restart would refuse this file)",
                  e.what());
    return;
  }
  if (!apply_log_level(next.log.level)) spdlog::error("reload: unknown log level {}", next.log.level);
  retrainer.set_settings(retrain_settings(next.model));
  const std::size_t held = store.size();
  store.set_limits(next.model.store_hours * 3600.0, next.model.max_samples);
  if (const std::size_t kept = store.size(); kept < held)
    spdlog::warn(
        "reload: the training store's new limits (model.store_hours {}, model.max_samples {}) drop {} "
        "of its {} pairs, the oldest; they are gone from {} at the next save",
        next.model.store_hours, next.model.max_samples, held - kept, held, state.store_path().string());
  if (pipeline) pipeline->set_tunables({next.gps.latency, next.tracker.min_snr_db});
  const auto restart = restart_required_changes(config, next);
  {
    // What was applied now replaces the running values (under the lock: the control thread reads them
    // for status); the rest stays as the threads use it. Recorded before it is said, as a refusal is.
    std::lock_guard lock(reload_mutex);
    reload_error.clear();
    restart_pending = restart;
    config.log = next.log;
    config.model.retrain_interval = next.model.retrain_interval;
    config.model.min_new_samples = next.model.min_new_samples;
    config.model.replace_min_samples = next.model.replace_min_samples;
    config.model.learn_cluster_pairs = next.model.learn_cluster_pairs;
    config.model.learn_first_refit = next.model.learn_first_refit;
    config.model.learn_young_time = next.model.learn_young_time;
    config.model.store_hours = next.model.store_hours;
    config.model.max_samples = next.model.max_samples;
    config.model.save_interval = next.model.save_interval;
    saver.set_save_interval(StateSaver::Seconds(next.model.save_interval));
    config.gps.latency = next.gps.latency;
    config.tracker.min_snr_db = next.tracker.min_snr_db;
  }
  for (const auto& key : restart)
    spdlog::warn("reload: {} changed; this takes effect only after a restart", key);
  spdlog::info(
      "reload: applied log level, retrain settings, training store limits, GPS latency, SNR threshold");
}

std::vector<std::string> Daemon::Impl::problems() const {
  std::vector<std::string> all = state.problems();
  if (const auto writing = saver.busy_for(); writing >= kSlowWrite)
    all.push_back(
        fmt::format("a write of training.bin or its journal has run for {:.0f} s (is the state "
                    "directory's disk failing?)",
                    writing.count()));
  return all;
}

control::StatusReply Daemon::Impl::status() {
  // What a reload applies, the main thread changes under the lock.
  Config running;
  std::string reload_said;
  std::vector<std::string> pending;
  {
    std::lock_guard lock(reload_mutex);
    running = config;
    reload_said = reload_error;
    pending = restart_pending;
  }
  StatusInputs in{.config = running,
                  .config_path = config_path,
                  .pipeline = pipeline ? pipeline->snapshot() : PipelineSnapshot{},
                  .model = model.get(),
                  .retrainer = retrainer.status(),
                  .training_samples = store.size(),
                  .new_samples = store.new_samples(),
                  .problems = problems(),
                  .reload_error = std::move(reload_said),
                  .restart_pending = std::move(pending),
                  .clients = control ? control->clients() : 0,
                  .uptime = std::chrono::duration<double>(Clock::now() - started).count()};
  return status_reply(in);
}

std::string Daemon::Impl::status_line() {
  const PipelineSnapshot p = pipeline ? pipeline->snapshot() : PipelineSnapshot{};
  const ModelPtr m = model.get();
  return fmt::format("{:.1f} km/h from {}, gear {}, model {}, gps {}, audio {}", p.speed * 3.6,
                     source_name(p.source), p.gear,
                     m && !m->empty() ? fmt::format("{} gears", m->gears.size()) : std::string("learning"),
                     to_string(p.gps_state), to_string(p.audio_state));
}

Daemon::Daemon(Config config, std::string config_path, Retrainer::Fitter fitter)
    : impl_(std::make_unique<Impl>(std::move(config), std::move(config_path), std::move(fitter))) {}

Daemon::~Daemon() = default;

int Daemon::run() {
  Impl& d = *impl_;
  // Signals are taken synchronously on this thread; every thread started later inherits the mask.
  sigset_t mask;
  sigemptyset(&mask);
  for (int sig : {SIGTERM, SIGINT, SIGHUP})
    sigaddset(&mask, sig);
  if (pthread_sigmask(SIG_BLOCK, &mask, nullptr) != 0) {
    spdlog::critical("cannot block signals");
    return 1;
  }
  const UniqueFd sfd(signalfd(-1, &mask, SFD_CLOEXEC | SFD_NONBLOCK));
  if (!sfd) {
    spdlog::critical("signalfd failed: {}", std::strerror(errno));
    return 1;
  }
  ::signal(SIGPIPE, SIG_IGN);

  if (!d.state.load()) return 1;
  try {
    d.control.emplace(d.config.control.socket,
                      ControlHandler(d.model, d.store, d.retrainer, d.state, [&d] { return d.status(); }),
                      ControlLimits{.max_clients = d.config.control.max_clients});
  } catch (const std::exception& e) {
    spdlog::critical("control: {}; exiting", e.what());
    return 1;
  }
  d.pipeline.emplace(d.config, d.model, d.store);
  d.pipeline->start();
  d.retrainer.start();
  d.control->start();
  spdlog::info("gearpulsed ready: control socket {}, output {}, state in {}", d.config.control.socket,
               to_string(d.config.output.kind), d.state.path().string());
  systemd::ready(d.status_line());

  const auto watchdog = systemd::watchdog_interval();
  const auto tick = watchdog.count() > 0
                        ? std::min<std::chrono::milliseconds>(
                              std::chrono::duration_cast<std::chrono::milliseconds>(watchdog / 3),
                              std::chrono::milliseconds(1000))
                        : std::chrono::milliseconds(1000);
  auto last_status = Clock::now();
  std::string last_line;
  WatchdogGate gate([watchdog] {
    if (watchdog.count() > 0) systemd::watchdog();
  });
  PipelineSnapshot previous = d.pipeline->snapshot();
  bool slow_write = false;  // said while it lasts
  d.saver.start();
  bool running = true;
  while (running) {
    pollfd pfd{sfd.get(), POLLIN, 0};
    const int n = ::poll(&pfd, 1, static_cast<int>(std::max<long long>(tick.count(), 50)));
    if (n > 0) {
      signalfd_siginfo info{};
      while (::read(sfd.get(), &info, sizeof info) == static_cast<ssize_t>(sizeof info)) {
        if (info.ssi_signo == SIGHUP) {
          d.reload();
        } else {
          spdlog::info("received {}; stopping", info.ssi_signo == SIGTERM ? "SIGTERM" : "SIGINT");
          running = false;
        }
      }
    }
    const auto now = Clock::now();
    d.pipeline->service();
    d.pipeline->drain_pairs();
    const PipelineSnapshot snap = d.pipeline->snapshot();
    // The watchdog is fed only while every pipeline thread shows a recent heartbeat: a hung thread
    // lets systemd restart the daemon.
    if (gate.tick(snap.stalled))
      spdlog::error("pipeline: thread(s) not responding: {}; withholding the watchdog so systemd restarts us",
                    fmt::join(snap.stalled, ", "));
    d.changes.log(previous, snap);
    previous = snap;
    if (now - last_status >= std::chrono::seconds(2)) {
      last_status = now;
      std::string line = d.status_line();
      if (line != last_line) systemd::status(line);
      last_line = std::move(line);
    }
    if (const bool slow = d.saver.busy_for() >= kSlowWrite; slow != slow_write) {
      slow_write = slow;
      if (slow)
        spdlog::warn(
            "training: a write to {} has run for over {} s; pulses and learning go on while it lasts",
            d.state.path().string(), std::chrono::duration_cast<std::chrono::seconds>(kSlowWrite).count());
      else
        spdlog::info("training: the slow write to {} is over", d.state.path().string());
    }
  }

  systemd::stopping();
  d.control->stop();
  // What is learned is saved first: joining a fit in progress (an idle-priority thread), the capture
  // thread (a device that does not return from a read) or a GPS client inside a connection attempt may
  // outlast systemd's stop timeout, and its SIGKILL must not cost the pairs since the last periodic save.
  d.pipeline->halt();  // output left low, no more training pairs asked for
  d.pipeline->drain_pairs();
  d.saver.stop();  // after the write in progress, if any
  d.state.save_or_journal();
  d.state.save_model();
  d.pipeline->stop();
  // Pairs the tracker made in its last turn, between halt() and its end.
  if (d.pipeline->drain_pairs() > 0) d.state.save_or_journal();
  d.retrainer.stop();
  d.control.reset();
  spdlog::info("gearpulsed stopped");
  return 0;
}

}  // namespace gearpulse::daemon
