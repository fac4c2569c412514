#include "daemon/daemon.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/signalfd.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <mutex>
#include <optional>
#include <vector>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "common/atomic_file.hpp"
#include "daemon/control_server.hpp"
#include "daemon/fitter.hpp"
#include "daemon/log_limiter.hpp"
#include "daemon/model_store.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/systemd_notify.hpp"
#include "daemon/training_store.hpp"
#include "daemon/watchdog.hpp"
#include "drivers/unique_fd.hpp"

namespace gearpulse::daemon {
namespace {

using Clock = std::chrono::steady_clock;

// Between saves of the training store the new pairs are journaled this often: a power cut (a car PC
// without a shutdown controller loses power with the ignition) costs at most this much learning, for a
// few hundred bytes and one sync per interval.
constexpr std::chrono::seconds kJournalInterval{10};

std::vector<control::GearRow> gear_rows(const ModelPtr& model) {
  std::vector<control::GearRow> gears;
  if (!model) return gears;
  int index = 1;
  for (const Gear& g : model->gears)
    gears.push_back({.gear = index++, .theta = g.theta, .std_error = g.std_error, .weight = g.weight});
  return gears;
}

// The gears the model knows, with the training pairs on each one's line at its fit (null when the model
// does not say) and whether a refit kept it from the model before (docs/cold-start.md).
std::vector<control::KnownGear> known_gears(const ModelPtr& model) {
  std::vector<control::KnownGear> gears;
  if (!model) return gears;
  const auto revs = model->extra.find("revs");
  const bool counted = revs != model->extra.end() && revs->is_array() && revs->size() == model->gears.size();
  const auto kept = model->extra.find(kKeptGears);
  for (std::size_t i = 0; i < model->gears.size(); ++i) {
    const Gear& g = model->gears[i];
    const bool was_kept = kept != model->extra.end() && kept->is_array() &&
                          std::find(kept->begin(), kept->end(), nlohmann::json(g.theta)) != kept->end();
    gears.push_back({.gear = static_cast<int>(i + 1),
                     .theta = g.theta,
                     .std_error = g.std_error,
                     .pairs = counted ? (*revs)[i].value("samples", nlohmann::json(nullptr)) : nullptr,
                     .kept = was_kept});
  }
  return gears;
}

control::ModelState model_state(const ModelPtr& model) {
  return model && !model->empty() ? control::ModelState::kTrained : control::ModelState::kLearning;
}

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
  return true;
}

struct Daemon::Impl {
  Impl(Config c, std::string path, Retrainer::Fitter fitter)
      : config(std::move(c)),
        config_path(std::move(path)),
        state_dir(config.model.state_dir),
        model_path(state_dir / "model.json"),
        store_path(state_dir / "training.bin"),
        store(config.model.store_hours * 3600.0, config.model.max_samples),
        retrainer(store, model, model_path, std::move(fitter), retrain_settings(config.model)) {}

  Config config;
  std::string config_path;
  std::filesystem::path state_dir;
  std::filesystem::path model_path;
  std::filesystem::path store_path;
  // Members are destroyed in reverse order: the state directory's lock outlives the retrainer and the
  // pipeline (which may still save into it), and the control server goes first (its thread reads all of
  // these), also when run() leaves by an exception before its orderly stop.
  std::optional<DirectoryLock> state_lock;
  ModelHolder model;
  TrainingStore store;
  Retrainer retrainer;
  std::optional<Pipeline> pipeline;
  Clock::time_point started = Clock::now();
  std::uint64_t pairs_at_last_save = 0;

  // Problems with the state directory that status reports: what was found at start (a file set aside
  // as corrupt, a directory that cannot be written) and the last failed save, cleared when one works.
  mutable std::mutex state_mutex;
  std::vector<std::string> state_problems;
  FaultSpell save_fault;                     // the training store's saves failing (the last one's error)
  std::string reload_error;                  // the last SIGHUP's file was refused ("" = it was taken)
  std::vector<std::string> restart_pending;  // changed by the last reload, waiting for a restart
  void note_state_problem(std::string text);
  static constexpr int kMaxSetAside = 100;  // copies of a file kept as NAME.corrupt[.N]
  [[nodiscard]] std::string set_aside(const std::filesystem::path& path);

  // False when another gearpulsed keeps its state in state_dir.
  [[nodiscard]] bool load_state();
  bool save_store(const char* why) noexcept;  // false when it failed (logged, and in status)
  void journal_store() noexcept;
  // At stop: a store that cannot be saved (disk full) may still take the few records of a journal append;
  // what neither takes is lost, and said so. A store the file already holds is not written again (a full
  // one is 24 MB, on flash that wears).
  void save_or_journal() noexcept {
    std::error_code ec;
    const bool due = store.unsaved() || !std::filesystem::exists(store_path, ec);
    if (!due || save_store("shutdown")) return;
    journal_store();
    if (const std::size_t lost = store.unkept(); lost > 0)
      spdlog::error(
          "training: {} pairs learned since the last save are lost: neither {} nor its journal "
          "could be written",
          lost, store_path.string());
  }
  void recover_journal() noexcept;
  FaultSpell journal_fault;  // journal appends failing (said once per spell); under state_mutex
  void reload();
  nlohmann::json handle(const nlohmann::json& json_request);
  void reset_model(bool keep_samples);  // throws ControlError
  nlohmann::json status_json();
  std::string status_line();
  void log_changes(const PipelineSnapshot& before, const PipelineSnapshot& now);
  LogLimiter limiter;
  StateFault no_reader;                  // the pulse output has no reader (a PTY nobody holds open)
  bool gps_connected = false;            // as log_changes() last said
  std::uint64_t gps_failures_seen = 0;   // GPS connection failures log_changes() has looked at
  std::optional<ControlServer> control;  // last: destroyed first (above)
};

// The journal gets one line per change of state (GPS lost or back, source switch, output errors), and
// repeated faults at most once a minute, so a log read at 2 a.m. tells what happened and when.
void Daemon::Impl::log_changes(const PipelineSnapshot& before, const PipelineSnapshot& now) {
  const std::string server = fmt::format("{}:{}", config.gps.host, config.gps.port);
  // From the connection itself, not from a change between two snapshots: the first connection is often
  // made before the first snapshot is taken.
  if (const bool up = now.gps_state != GpsState::kDisconnected; up != gps_connected) {
    gps_connected = up;
    if (up) spdlog::info("gps: connected to gpsd at {}", server);
  }
  if (now.gps_state != before.gps_state) {
    std::uint64_t suppressed = 0;
    if (now.gps_state == GpsState::kFix) {
      // The fault is over: the next one is reported at once.
      limiter.reset("gps");
      limiter.reset("gps-no-fix");
      spdlog::info("gps: fix from gpsd at {} ({:.1f} km/h)", server, std::max(0.0, now.gps_speed) * 3.6);
    } else if (now.gps_state == GpsState::kNoFix && limiter.allow("gps-no-fix", suppressed)) {
      // How long GPS has really been gone: after a reconnect that can be far more than the timeout.
      // (The source it switches to is said when it switches: after the timeout, not necessarily yet.)
      const std::string gone = now.gps_age >= 0.0 ? fmt::format("for {:.1f} s", now.gps_age) : "yet";
      spdlog::warn("gps: no usable fix from gpsd at {} {}{}", server, gone,
                   suppressed ? fmt::format(" ({} more times since the last report)", suppressed) : "");
    }
  }
  // A receiver's glitch refused: said at once, then at most once a minute with how many more.
  if (now.gps_implausible > before.gps_implausible) {
    std::uint64_t suppressed = 0;
    if (limiter.allow("gps-implausible", suppressed))
      spdlog::warn(
          "gps: a speed of {:.0f} km/h from gpsd at {} ignored (no car reaches it, or not that fast); "
          "{} such reports so far{}",
          now.gps_last_implausible * 3.6, server, now.gps_implausible,
          suppressed ? fmt::format(" ({} since the last report)", suppressed) : "");
  }
  // One count per failed attempt (the backoff spaces them), not per turn of this loop.
  if (now.gps_state == GpsState::kDisconnected && !now.gps_error.empty() &&
      now.gps_failures != gps_failures_seen) {
    gps_failures_seen = now.gps_failures;
    std::uint64_t suppressed = 0;
    if (limiter.allow("gps", suppressed))
      spdlog::warn(
          "gps: {}; reconnecting with backoff{}", now.gps_error,
          suppressed ? fmt::format(" ({} more failed attempts since the last report)", suppressed) : "");
  }
  if (now.source != before.source) {
    // Into and out of GPS is news; engine <-> coast inside an outage is every declutch (two per shift).
    const auto outage = [](SpeedSource s) { return s == SpeedSource::kEngine || s == SpeedSource::kCoast; };
    const bool routine = outage(before.source) && outage(now.source);
    spdlog::log(routine ? spdlog::level::debug : spdlog::level::info,
                "synthesis: speed source {} -> {} at {:.1f} km/h (gear {})", source_name(before.source),
                source_name(now.source), now.speed * 3.6, now.gear);
  }
  // A navigator that should be reading the pulses is not: said when the last reader goes (or none is
  // there at start) and when one comes, at most once a minute for a reader that opens and closes often.
  std::uint64_t starts = 0;
  switch (no_reader.update(now.output_state == OutputState::kNoReader, std::chrono::steady_clock::now(),
                           starts)) {
    case StateFault::Say::kStart:
      spdlog::warn(
          "output: no process has {} open; pulses are discarded and counted as unheard ({} so far){}",
          config.output.path, now.output_unheard,
          starts > 1 ? fmt::format(" ({} times since the last report)", starts) : "");
      break;
    case StateFault::Say::kEnd:
      spdlog::info("output: a reader has {} open ({} pulses went unheard in all)", config.output.path,
                   now.output_unheard);
      break;
    case StateFault::Say::kNothing:
      break;
  }
  if (now.output_state != before.output_state && now.output_state == OutputState::kWriteErrors)
    spdlog::warn("output: writes to {} are failing; pulses are counted but not delivered",
                 config.output.path);
  if (now.output_dropped > before.output_dropped) {
    std::uint64_t suppressed = 0;
    if (limiter.allow("output-dropped", suppressed))
      spdlog::warn(
          "output: the reader of {} is not reading: {} pulse(s) dropped (total {}); pulses that wait in "
          "its queue over 2 s are dropped rather than delivered late",
          config.output.path, now.output_dropped - before.output_dropped, now.output_dropped);
  } else if (before.output_state == OutputState::kReaderBehind &&
             now.output_state != OutputState::kReaderBehind) {
    limiter.reset("output-dropped");
    spdlog::info("output: the reader of {} keeps up again", config.output.path);
  }
  if (now.xruns > before.xruns) {
    std::uint64_t suppressed = 0;
    if (limiter.allow("xrun", suppressed))
      spdlog::warn("audio: {} overrun(s) on {} (total {}); the capture recovered", now.xruns - before.xruns,
                   config.audio.device, now.xruns);
  }
  if (now.ring_drops > before.ring_drops) {
    std::uint64_t suppressed = 0;
    if (limiter.allow("ring", suppressed))
      spdlog::warn("audio: the tracker fell behind, {} frames dropped at the ring (total {})",
                   now.ring_drops - before.ring_drops, now.ring_drops);
  }
  if (now.pairs_lost > before.pairs_lost) {
    std::uint64_t suppressed = 0;
    if (limiter.allow("pairs", suppressed))
      spdlog::warn("training: {} pair(s) lost waiting for the main thread (total {})",
                   now.pairs_lost - before.pairs_lost, now.pairs_lost);
  }
}

void Daemon::Impl::note_state_problem(std::string text) {
  std::lock_guard lock(state_mutex);
  state_problems.push_back(std::move(text));
}

// A file that will not load is moved aside to NAME.corrupt (replacing an older one), so the next save
// does not overwrite what someone may want to look at or recover. Returns where it is now, for the log
// ("kept as NAME.corrupt", or "left where it is" if it could not be moved).
std::string Daemon::Impl::set_aside(const std::filesystem::path& path) {
  // A name not yet taken: the evidence of an earlier corruption is kept too. A name that cannot be looked
  // up (a directory the daemon may not search) ends the search: it would never find a free one.
  std::filesystem::path aside = path;
  aside += ".corrupt";
  std::error_code ec;
  for (int n = 1; n <= kMaxSetAside; ++n) {
    const auto type = std::filesystem::symlink_status(aside, ec).type();
    if (type == std::filesystem::file_type::not_found) {
      std::filesystem::rename(path, aside, ec);
      return ec ? "left where it is: " + ec.message() : "kept as " + aside.string();
    }
    if (ec) return "left where it is: " + ec.message();
    aside = path;
    aside += ".corrupt." + std::to_string(n);
  }
  return "left where it is: " + std::to_string(kMaxSetAside) + " copies are set aside already";
}

bool Daemon::Impl::load_state() {
  std::error_code ec;
  std::filesystem::create_directories(state_dir, ec);
  if (ec) {
    spdlog::error("state: cannot create {}: {}; the model and training pairs will not survive a restart",
                  state_dir.string(), ec.message());
    note_state_problem("cannot create " + state_dir.string() + ": " + ec.message());
    return true;  // nothing there to load (a model.json "ignored" under it would only mislead)
  } else {
    try {
      state_lock.emplace(state_dir);
      if (!state_lock->held()) {
        spdlog::critical("state: another gearpulsed keeps its state in {}; exiting", state_dir.string());
        return false;
      }
    } catch (const std::exception& e) {
      spdlog::warn("state: {}; nothing stops a second daemon from sharing {}", e.what(), state_dir.string());
    }
    // Said now, not at the first save minutes later (or at shutdown).
    // A block is written and synced, so that a full disk shows as well as a read-only one.
    const std::filesystem::path probe = state_dir / ".gearpulse-write-test";
    UniqueFd fd(::open(probe.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600));
    int err = fd ? 0 : errno;
    if (fd) {
      static constexpr char kBlock[4096] = {};
      const ssize_t n = ::write(fd.get(), kBlock, sizeof kBlock);
      if (n != static_cast<ssize_t>(sizeof kBlock)) err = n < 0 ? errno : ENOSPC;
      if (err == 0 && ::fdatasync(fd.get()) != 0) err = errno;
      fd.reset();
      ::unlink(probe.c_str());
    }
    if (err != 0) {
      const std::string why = std::strerror(err);
      spdlog::error("state: cannot write in {}: {}; the model and training pairs will not survive a restart",
                    state_dir.string(), why);
      note_state_problem("cannot write in " + state_dir.string() + ": " + why);
    } else if (struct statvfs fs{}; ::statvfs(state_dir.c_str(), &fs) == 0) {
      // A full store is replaced by writing the new one beside it: room for two is needed.
      const double free_bytes = static_cast<double>(fs.f_bavail) * static_cast<double>(fs.f_frsize);
      const double need = 2.0 * TrainingStore::file_bytes(config.model.max_samples);
      if (free_bytes < need) {
        const std::string text = fmt::format(
            "only {:.1f} MB free in {}; a full training store (model.max_samples = {}) needs {:.1f} MB "
            "while it is saved",
            free_bytes / 1e6, state_dir.string(), config.model.max_samples, need / 1e6);
        spdlog::warn("state: {}", text);
        note_state_problem(text);
      }
    }
  }
  // A crash between writing a temp file and renaming it leaves the temp file; the real file is intact.
  for (const auto& p : {model_path, store_path, TrainingStore::journal_path(store_path)})
    if (const std::size_t n = remove_stale_temp_files(p))
      spdlog::info("state: removed {} temp file(s) of an interrupted save of {}", n, p.string());

  const std::optional<FileStamp> stamp = stamp_of(model_path);
  const ModelLoad loaded = load_model_file(model_path);
  if (loaded.model) {
    model.set(loaded.model);
    model.set_file_stamp(stamp);
    spdlog::info("model: loaded {} ({} gears, fitted on {} samples)", model_path.string(),
                 loaded.model->gears.size(), loaded.model->samples);
  } else if (!loaded.error.empty()) {
    // Set aside, whether for its content or because it cannot be read (a file another user installed
    // with mode 0600): the daemon's own saves then go to a fresh file and never over it.
    const std::string where = set_aside(model_path);
    spdlog::error("model: ignoring {}: {}; learning from scratch (the file is {})", model_path.string(),
                  loaded.error, where);
    note_state_problem("model.json ignored: " + loaded.error + " (" + where + ")");
  } else {
    spdlog::info("model: no {} yet; pulses follow GPS while the model is learning", model_path.string());
  }

  try {
    const std::string problem = store.load(store_path);
    if (!problem.empty()) {
      const std::string where = set_aside(store_path);
      spdlog::error("training: discarding {}: {}; starting with an empty training store (the file is {})",
                    store_path.string(), problem, where);
      note_state_problem("training.bin discarded: " + problem + " (" + where + ")");
    } else if (std::filesystem::exists(store_path)) {
      spdlog::info("training: {} stored pairs restored from {}", store.size(), store_path.string());
      if (const std::size_t skipped = store.skipped(); skipped > 0) {
        const std::string text = fmt::format(
            "training.bin: {} record(s) hold their checksum but no plausible pair; skipped ({} pairs "
            "restored)",
            skipped, store.size());
        spdlog::warn("training: {}", text);
        note_state_problem(text);
      }
    } else
      spdlog::info("training: no stored pairs yet ({} will hold them)", store_path.string());
  } catch (const std::exception& e) {
    // Set aside as a corrupt store is (a file another user installed with mode 0600, a read error): the
    // store's saves replace the file whole, and would otherwise put the few pairs of this run over the
    // history it holds.
    const std::string where = set_aside(store_path);
    spdlog::error("training: cannot read {}: {}; starting with an empty training store (the file is {})",
                  store_path.string(), e.what(), where);
    note_state_problem("training.bin unreadable: " + std::string(e.what()) + " (" + where + ")");
  }
  recover_journal();
  // Pairs stored after the model's last fit are new to it, whichever run gathered them.
  if (const ModelPtr m = model.get()) {
    const auto until = m->extra.find(kTrainedUntil);
    const auto last = m->extra.find(kTrainedLast);
    if (last != m->extra.end() && last->is_array() && last->size() == 3 && (*last)[0].is_number() &&
        (*last)[1].is_number() && (*last)[2].is_number() &&
        store.set_new_after_pair(
            {(*last)[0].get<double>(), (*last)[1].get<double>(), (*last)[2].get<double>()})) {
      spdlog::info("training: {} of the {} stored pairs were stored after the model's last fit",
                   store.new_samples(), store.size());
    } else if (until != m->extra.end() && until->is_number()) {
      store.set_new_after(until->get<double>());
      spdlog::info("training: {} of the {} stored pairs are newer than the model's last fit",
                   store.new_samples(), store.size());
    } else if (store.size() > 0) {
      // A model this daemon did not fit (`gearpulse fit --out` from a log) has seen none of them.
      store.set_new_after(-std::numeric_limits<double>::infinity());
      spdlog::info(
          "training: the model was not fitted by gearpulsed (no extra.{}): all {} stored pairs are new "
          "to it",
          kTrainedUntil, store.size());
    }
  }
  return true;
}

// Pairs journaled after the last save of the store: what the previous run learned before it lost power.
void Daemon::Impl::recover_journal() noexcept {
  const std::filesystem::path journal = TrainingStore::journal_path(store_path);
  try {
    const TrainingStore::JournalReplay replay = store.replay_journal(store_path);
    if (!replay.problem.empty()) {
      spdlog::warn("training: {}: {}", journal.string(), replay.problem);
      note_state_problem(journal.filename().string() + ": " + replay.problem);
    }
    if (replay.stale)
      spdlog::debug("training: {} predates the last save; nothing to recover", journal.string());
    if (replay.recovered > 0) {
      spdlog::info("training: {} pairs recovered from {} (the last run ended without saving them)",
                   replay.recovered, journal.string());
      save_store("journal recovered");
    }
  } catch (const std::exception& e) {
    spdlog::error("training: cannot read {}: {}; pairs of the last run since its last save are lost",
                  journal.string(), e.what());
    note_state_problem(journal.filename().string() + " unreadable: " + e.what());
  }
}

void Daemon::Impl::journal_store() noexcept {
  try {
    const std::size_t n = store.append_journal(store_path);
    if (n > 0) spdlog::trace("training: journaled {} pairs", n);
    std::lock_guard lock(state_mutex);
    if (journal_fault.succeeded())
      spdlog::info("training: {} written again", TrainingStore::journal_path(store_path).string());
  } catch (const std::exception& e) {
    // Said once per failing spell, not every few seconds, and shown in status while it lasts (the
    // periodic save, minutes apart, may not have failed yet).
    try {
      std::lock_guard lock(state_mutex);
      if (journal_fault.failed(std::string("cannot journal training pairs: ") + e.what()))
        spdlog::error("training: cannot write {}: {}; pairs since the last save are at risk until it works",
                      TrainingStore::journal_path(store_path).string(), e.what());
    } catch (...) {
    }
  }
}

bool Daemon::Impl::save_store(const char* why) noexcept {
  try {
    store.save(store_path);
    spdlog::debug("training: saved {} pairs to {} ({})", store.size(), store_path.string(), why);
    std::lock_guard lock(state_mutex);
    if (save_fault.succeeded()) spdlog::info("training: {} saved again ({})", store_path.string(), why);
    return true;
  } catch (const std::exception& e) {
    try {
      std::lock_guard lock(state_mutex);
      // A periodic save that keeps failing the same way is said once per spell (status keeps saying
      // it); a save at shutdown or reset is said every time.
      if (save_fault.failed(std::string("cannot save training.bin: ") + e.what()) ||
          std::string_view(why) != "periodic")
        spdlog::error("training: cannot save {} ({}): {}", store_path.string(), why, e.what());
    } catch (...) {
    }
  }
  return false;
}

void Daemon::Impl::reload() {
  spdlog::info("reload: re-reading {}", config_path);
  Config next;
  try {
    next = load_config(config_path);
  } catch (const ConfigError& e) {
    spdlog::error("reload: {}; keeping the running configuration (a restart would refuse this file)",
                  e.what());
    std::lock_guard lock(state_mutex);
    reload_error = e.what();
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
        next.model.store_hours, next.model.max_samples, held - kept, held, store_path.string());
  if (pipeline) pipeline->set_tunables({next.gps.latency, next.tracker.min_snr_db});
  const auto restart = restart_required_changes(config, next);
  for (const auto& key : restart)
    spdlog::warn("reload: {} changed; this takes effect only after a restart", key);
  {
    std::lock_guard lock(state_mutex);
    reload_error.clear();
    restart_pending = restart;
  }
  // What was applied now replaces the running values; the rest stays as the threads use it.
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
  config.gps.latency = next.gps.latency;
  config.tracker.min_snr_db = next.tracker.min_snr_db;
  spdlog::info(
      "reload: applied log level, retrain settings, training store limits, GPS latency, SNR threshold");
}

nlohmann::json Daemon::Impl::status_json() {
  const PipelineSnapshot p = pipeline ? pipeline->snapshot() : PipelineSnapshot{};
  const ModelPtr m = model.get();
  const Retrainer::Status r = retrainer.status();
  using control::number_if;
  control::StatusReply reply;
  reply.speed = p.speed;
  reply.speed_kmh = p.speed * 3.6;
  reply.source = source_name(p.source);
  reply.gear = p.gear;
  reply.pulses = p.pulses;
  reply.pulse_frequency = p.pulse_frequency;
  reply.gears = gear_rows(m);
  reply.model_state = model_state(m);
  reply.training_samples = store.size();
  reply.uptime = std::chrono::duration<double>(Clock::now() - started).count();
  reply.output = {.kind = to_string(config.output.kind),
                  .state = std::string(to_string(p.output_state)),
                  .error = p.output_error,
                  .dropped = p.output_dropped,
                  .unheard = p.output_unheard,
                  .pulses_per_km = config.output.pulses_per_km,
                  .path = std::nullopt};
  if (config.output.kind == OutputKind::kPty) reply.output.path = config.output.path;
  if (config.output.kind == OutputKind::kGpio)
    reply.output.path = fmt::format("{}:{}", config.output.chip, config.output.line);
  reply.gps = {.state = std::string(to_string(p.gps_state)),
               .speed = number_if(p.gps_speed, p.gps_speed >= 0),
               .mode = p.gps_mode,
               .age = number_if(p.gps_age, p.gps_age >= 0),
               .reconnects = p.gps_reconnects,
               .implausible = p.gps_implausible,
               .server = fmt::format("{}:{}", config.gps.host, config.gps.port),
               .error = p.gps_error};
  reply.audio = {.state = std::string(to_string(p.audio_state)),
                 .device = config.audio.device,
                 .rate = config.audio.rate,
                 .xruns = p.xruns,
                 .ring_drops = p.ring_drops,
                 .error = p.audio_error};
  reply.tracker = {.freq = number_if(p.tracker_freq, p.tracker_freq >= 0),
                   .snr_db = number_if(p.tracker_snr_db, p.tracker_freq >= 0),
                   .confident = p.tracker_confident};
  reply.model = {.state = model_state(m),
                 .gears = m ? m->gears.size() : 0,
                 .fit_samples = m ? m->samples : 0,
                 .training_samples = store.size(),
                 .new_samples = store.new_samples(),
                 .retrain_runs = r.runs,
                 .retrain_busy = r.busy,
                 .last_retrain = number_if(r.last_run_wall, r.runs > 0),
                 .last_result = r.last_result,
                 .reason = std::nullopt,
                 .known_gears = known_gears(m),
                 .learning = {.young = r.young,
                              .moving_time = r.moving_time,
                              .next_refit = number_if(r.next_refit, r.next_refit >= 0.0),
                              .cluster_pairs = r.cluster_pairs,
                              .first_fit_pairs = config.model.learn_cluster_pairs},
                 .problems = {}};
  if (m && m->empty() && !m->reason.empty()) reply.model.reason = m->reason;
  {
    std::lock_guard lock(state_mutex);
    // The state directory's: files set aside, failed saves.
    reply.model.problems = state_problems;
    if (save_fault.failing()) reply.model.problems.push_back(save_fault.what());
    if (journal_fault.failing()) reply.model.problems.push_back(journal_fault.what());
    reply.config = {.file = config_path, .reload_error = reload_error, .restart_pending = restart_pending};
  }
  reply.threads = {.stalled = p.stalled, .missing = p.missing};
  reply.clients = control ? control->clients() : 0;
  return control::to_json(reply);
}

nlohmann::json Daemon::Impl::handle(const nlohmann::json& json_request) {
  const control::Request request = control::parse_request(json_request);
  switch (request.command) {
    case control::Command::kStatus:
      return status_json();
    case control::Command::kGears: {
      const ModelPtr m = model.get();
      return control::to_json(control::GearsReply{.gears = gear_rows(m),
                                                  .model_state = model_state(m),
                                                  .model = m ? model_to_json(*m) : nlohmann::json(nullptr),
                                                  .training_samples = store.size()});
    }
    case control::Command::kRetrain:
      retrainer.request();
      spdlog::info("control: retrain requested ({} training pairs)", store.size());
      return control::to_json(control::RetrainReply{.queued = true, .training_samples = store.size()});
    case control::Command::kResetModel:
      reset_model(request.keep_samples);
      return control::to_json(control::ResetReply{.reset = true, .training_samples = store.size()});
  }
  throw ControlError("unknown command");
}

void Daemon::Impl::reset_model(bool keep) {
  {
    // A fit running now finds the generation changed and discards its result.
    const auto lock = model.lock_writes();
    model.set(nullptr);
    try {
      remove_file_durable(model_path);
      model.set_file_stamp(std::nullopt);
    } catch (const std::exception& e) {
      throw ControlError(e.what());
    }
  }
  if (!keep) {
    store.clear();
    // The file that cannot be replaced still holds the cleared pairs, and the next start would bring
    // them back: it goes (with its journal), or the reply says it stays.
    if (!save_store("reset-model")) {
      try {
        remove_file_durable(TrainingStore::journal_path(store_path));
        remove_file_durable(store_path);
      } catch (const std::exception& e) {
        throw ControlError(fmt::format(
            "the model is forgotten, but the training pairs cannot be cleared from {} ({}): they come "
            "back at the next start",
            store_path.string(), e.what()));
      }
    }
  }
  spdlog::warn("control: model reset{}; pulses follow GPS while the model is learning again",
               keep ? " (training pairs kept)" : " and training pairs cleared");
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

  if (!d.load_state()) return 1;
  try {
    d.control.emplace(
        d.config.control.socket, [&d](const nlohmann::json& req) { return d.handle(req); },
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
               to_string(d.config.output.kind), d.state_dir.string());
  systemd::ready(d.status_line());

  const auto watchdog = systemd::watchdog_interval();
  const auto tick = watchdog.count() > 0
                        ? std::min<std::chrono::milliseconds>(
                              std::chrono::duration_cast<std::chrono::milliseconds>(watchdog / 3),
                              std::chrono::milliseconds(1000))
                        : std::chrono::milliseconds(1000);
  auto last_save = Clock::now();
  auto last_journal = Clock::now();
  auto last_status = Clock::now();
  std::string last_line;
  WatchdogGate gate([watchdog] {
    if (watchdog.count() > 0) systemd::watchdog();
  });
  PipelineSnapshot previous = d.pipeline->snapshot();
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
    d.log_changes(previous, snap);
    previous = snap;
    if (now - last_status >= std::chrono::seconds(2)) {
      last_status = now;
      std::string line = d.status_line();
      if (line != last_line) systemd::status(line);
      last_line = std::move(line);
    }
    if (now - last_save >= std::chrono::duration<double>(d.config.model.save_interval)) {
      last_save = last_journal = now;
      if (snap.pairs_added != d.pairs_at_last_save) {
        // A save that fails (a full disk) leaves the journal to keep the pairs, however short the save
        // interval: with saves due before every journal append, none was written once.
        if (d.save_store("periodic"))
          d.pairs_at_last_save = snap.pairs_added;
        else
          d.journal_store();
      }
    } else if (now - last_journal >= kJournalInterval) {
      last_journal = now;
      d.journal_store();
    }
  }

  systemd::stopping();
  d.control->stop();
  // What is learned is saved first: joining a fit in progress (an idle-priority thread), the capture
  // thread (a device that does not return from a read) or a GPS client inside a connection attempt may
  // outlast systemd's stop timeout, and its SIGKILL must not cost the pairs since the last periodic save.
  d.pipeline->halt();  // output left low, no more training pairs asked for
  d.pipeline->drain_pairs();
  d.save_or_journal();
  {
    const auto lock = d.model.lock_writes();
    if (const ModelPtr m = d.model.get(); m && !m->empty()) {
      try {
        // Written only if the file does not already hold it (a model unchanged since it was loaded or
        // saved is not rewritten at every stop, on media that may be read-only or worn), and never over
        // a model.json installed while the daemon ran.
        if (save_model_if_ours(d.model, d.model_path, *m) == ModelSave::kReplacedByOther)
          spdlog::warn(
              "model: {} was replaced while gearpulsed ran; left as it is (it is loaded at the next "
              "start), so the model in use is not saved",
              d.model_path.string());
      } catch (const std::exception& e) {
        spdlog::error("model: cannot save {} at shutdown: {}", d.model_path.string(), e.what());
      }
    }
  }
  d.pipeline->stop();
  // Pairs the tracker made in its last turn, between halt() and its end.
  if (d.pipeline->drain_pairs() > 0) d.save_or_journal();
  d.retrainer.stop();
  d.control.reset();
  spdlog::info("gearpulsed stopped");
  return 0;
}

}  // namespace gearpulse::daemon
