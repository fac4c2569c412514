#include "daemon/state_directory.hpp"

#include <fcntl.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string_view>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "daemon/retrainer.hpp"
#include "drivers/unique_fd.hpp"

namespace gearpulse::daemon {

std::string state_dir_advice(const std::filesystem::path& dir) {
  return fmt::format(
      "check that model.state_dir ({}) can be made, has room and may be written by gearpulsed's user; "
      "under the systemd unit (ProtectSystem=strict) only /var/lib/gearpulse is writable",
      dir.string());
}

StateDirectory::StateDirectory(std::filesystem::path dir, ModelHolder& model, TrainingStore& store,
                               std::size_t max_samples)
    : dir_(std::move(dir)),
      model_path_(dir_ / "model.json"),
      store_path_(dir_ / "training.bin"),
      model_(model),
      store_(store),
      max_samples_(max_samples) {}

void StateDirectory::note_problem(std::string text) {
  std::lock_guard lock(mutex_);
  problems_.push_back(std::move(text));
}

std::vector<std::string> StateDirectory::problems() const {
  std::lock_guard lock(mutex_);
  std::vector<std::string> all = problems_;
  if (save_fault_.failing()) all.push_back(save_fault_.what());
  if (journal_fault_.failing()) all.push_back(journal_fault_.what());
  return all;
}

std::string StateDirectory::set_aside(const std::filesystem::path& path) {
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

bool StateDirectory::load() {
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  if (ec) {
    spdlog::error("state: cannot create {}: {}; the model and training pairs will not survive a restart ({})",
                  dir_.string(), ec.message(), state_dir_advice(dir_));
    note_problem("cannot create " + dir_.string() + ": " + ec.message());
    return true;  // nothing there to load (a model.json "ignored" under it would only mislead)
  }
  try {
    lock_.emplace(dir_);
    if (!lock_->held()) {
      spdlog::critical("state: another gearpulsed keeps its state in {}; exiting", dir_.string());
      return false;
    }
  } catch (const std::exception& e) {
    spdlog::warn("state: {}; nothing stops a second daemon from sharing {}", e.what(), dir_.string());
  }
  probe_writes();
  // A crash between writing a temp file and renaming it leaves the temp file; the real file is intact.
  for (const auto& p : {model_path_, store_path_, TrainingStore::journal_path(store_path_)})
    if (const std::size_t n = remove_stale_temp_files(p))
      spdlog::info("state: removed {} temp file(s) of an interrupted save of {}", n, p.string());

  load_model();
  load_store();
  recover_journal();
  mark_new_pairs();
  return true;
}

// Said now, not at the first save minutes later (or at shutdown).
void StateDirectory::probe_writes() {
  // A block is written and synced, so that a full disk shows as well as a read-only one.
  const std::filesystem::path probe = dir_ / ".gearpulse-write-test";
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
    spdlog::error(
        "state: cannot write in {}: {}; the model and training pairs will not survive a restart ({})",
        dir_.string(), why, state_dir_advice(dir_));
    note_problem("cannot write in " + dir_.string() + ": " + why);
  } else if (struct statvfs fs{}; ::statvfs(dir_.c_str(), &fs) == 0) {
    // A full store is replaced by writing the new one beside it: room for two is needed.
    const double free_bytes = static_cast<double>(fs.f_bavail) * static_cast<double>(fs.f_frsize);
    const double need = 2.0 * TrainingStore::file_bytes(max_samples_);
    if (free_bytes < need) {
      const std::string text = fmt::format(
          "only {:.1f} MB free in {}; a full training store (model.max_samples = {}) needs {:.1f} MB "
          "while it is saved",
          free_bytes / 1e6, dir_.string(), max_samples_, need / 1e6);
      spdlog::warn("state: {}", text);
      note_problem(text);
    }
  }
}

void StateDirectory::load_model() {
  const std::optional<FileStamp> stamp = stamp_of(model_path_);
  const ModelLoad loaded = load_model_file(model_path_);
  if (loaded.model) {
    model_.set(loaded.model);
    model_.set_file_stamp(stamp);
    spdlog::info("model: loaded {} ({} gears, fitted on {} samples)", model_path_.string(),
                 loaded.model->gears.size(), loaded.model->samples);
  } else if (!loaded.error.empty()) {
    // Set aside, whether for its content or because it cannot be read (a file another user installed
    // with mode 0600): the daemon's own saves then go to a fresh file, and the file is kept.
    const std::string where = set_aside(model_path_);
    // Not set aside (every name taken, a rename refused): left as a file the daemon neither loaded nor
    // wrote, it would be taken for one installed while the daemon ran, and no fit would ever be saved over
    // it. It is the daemon's to replace instead.
    const std::optional<FileStamp> left = stamp_of(model_path_);
    if (left) model_.set_file_stamp(left);
    spdlog::error("model: ignoring {}: {}; learning from scratch (the file is {}){}", model_path_.string(),
                  loaded.error, where,
                  left ? "; gearpulsed's saves of its model replace it, and if they fail, delete it to let "
                         "gearpulsed save its model"
                       : "");
    note_problem("model.json ignored: " + loaded.error + " (" + where +
                 (left ? "; the model's saves replace it)" : ")"));
  } else {
    spdlog::info("model: no {} yet; pulses follow GPS while the model is learning", model_path_.string());
  }
}

void StateDirectory::load_store() {
  try {
    const std::string problem = store_.load(store_path_);
    if (!problem.empty()) {
      const std::string where = set_aside(store_path_);
      spdlog::error("training: discarding {}: {}; starting with an empty training store (the file is {})",
                    store_path_.string(), problem, where);
      note_problem("training.bin discarded: " + problem + " (" + where + ")");
    } else if (std::filesystem::exists(store_path_)) {
      spdlog::info("training: {} stored pairs restored from {}", store_.size(), store_path_.string());
      if (const std::size_t skipped = store_.skipped(); skipped > 0) {
        const std::string text = fmt::format(
            "training.bin: {} record(s) hold their checksum but no plausible pair; skipped ({} pairs "
            "restored)",
            skipped, store_.size());
        spdlog::warn("training: {}", text);
        note_problem(text);
      }
    } else
      spdlog::info("training: no stored pairs yet ({} will hold them)", store_path_.string());
  } catch (const std::exception& e) {
    // Set aside as a corrupt store is (a file another user installed with mode 0600, a read error): the
    // store's saves replace the file whole, and would otherwise put the few pairs of this run over the
    // history it holds.
    const std::string where = set_aside(store_path_);
    spdlog::error("training: cannot read {}: {}; starting with an empty training store (the file is {})",
                  store_path_.string(), e.what(), where);
    note_problem("training.bin unreadable: " + std::string(e.what()) + " (" + where + ")");
  }
}

// Pairs stored after the model's last fit are new to it, whichever run gathered them.
void StateDirectory::mark_new_pairs() {
  if (const ModelPtr m = model_.get()) {
    const auto until = m->extra.find(kTrainedUntil);
    const auto last = m->extra.find(kTrainedLast);
    if (last != m->extra.end() && last->is_array() && last->size() == 3 && (*last)[0].is_number() &&
        (*last)[1].is_number() && (*last)[2].is_number() &&
        store_.set_new_after_pair(
            {(*last)[0].get<double>(), (*last)[1].get<double>(), (*last)[2].get<double>()})) {
      spdlog::info("training: {} of the {} stored pairs were stored after the model's last fit",
                   store_.new_samples(), store_.size());
    } else if (until != m->extra.end() && until->is_number()) {
      store_.set_new_after(until->get<double>());
      spdlog::info("training: {} of the {} stored pairs are newer than the model's last fit",
                   store_.new_samples(), store_.size());
    } else if (store_.size() > 0) {
      // A model this daemon did not fit (`gearpulse fit --out` from a log) has seen none of them.
      store_.set_new_after(-std::numeric_limits<double>::infinity());
      spdlog::info(
          "training: the model was not fitted by gearpulsed (no extra.{}): all {} stored pairs are new "
          "to it",
          kTrainedUntil, store_.size());
    }
  }
}

// Pairs journaled after the last save of the store: what the previous run learned before it lost power.
void StateDirectory::recover_journal() noexcept {
  const std::filesystem::path journal = TrainingStore::journal_path(store_path_);
  try {
    const TrainingStore::JournalReplay replay = store_.replay_journal(store_path_);
    if (!replay.problem.empty()) {
      spdlog::warn("training: {}: {}", journal.string(), replay.problem);
      note_problem(journal.filename().string() + ": " + replay.problem);
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
    note_problem(journal.filename().string() + " unreadable: " + e.what());
  }
}

void StateDirectory::journal_store() noexcept {
  try {
    const std::size_t n = store_.append_journal(store_path_);
    if (n > 0) spdlog::trace("training: journaled {} pairs", n);
    std::lock_guard lock(mutex_);
    if (journal_fault_.succeeded())
      spdlog::info("training: {} written again", TrainingStore::journal_path(store_path_).string());
  } catch (const std::exception& e) {
    // Said once per failing spell, not every few seconds, and shown in status while it lasts (the
    // periodic save, minutes apart, may not have failed yet).
    try {
      std::lock_guard lock(mutex_);
      if (journal_fault_.failed(std::string("cannot journal training pairs: ") + e.what()))
        spdlog::error("training: cannot write {}: {}; pairs since the last save are at risk until it works",
                      TrainingStore::journal_path(store_path_).string(), e.what());
    } catch (...) {
    }
  }
}

bool StateDirectory::save_store(const char* why) noexcept {
  try {
    store_.save(store_path_);
    // Recorded before it is said (whoever reads the line and then asks for status finds the fault gone),
    // and said under the lock, so a save failing meanwhile on another thread is said after it, not before.
    {
      std::lock_guard lock(mutex_);
      if (save_fault_.succeeded()) spdlog::info("training: {} saved again ({})", store_path_.string(), why);
    }
    spdlog::debug("training: saved {} pairs to {} ({})", store_.size(), store_path_.string(), why);
    return true;
  } catch (const std::exception& e) {
    try {
      std::lock_guard lock(mutex_);
      // A periodic save that keeps failing the same way is said once per spell (status keeps saying
      // it); a save at shutdown or reset is said every time.
      if (save_fault_.failed(std::string("cannot save training.bin: ") + e.what()) ||
          std::string_view(why) != "periodic")
        spdlog::error("training: cannot save {} ({}): {}; {}", store_path_.string(), why, e.what(),
                      state_dir_advice(dir_));
    } catch (...) {
    }
  }
  return false;
}

void StateDirectory::save_or_journal() noexcept {
  std::error_code ec;
  const bool due = store_.unsaved() || !std::filesystem::exists(store_path_, ec);
  if (!due || save_store("shutdown")) return;
  journal_store();
  if (const std::size_t lost = store_.unkept(); lost > 0)
    spdlog::error(
        "training: {} pairs learned since the last save are lost: neither {} nor its journal "
        "could be written",
        lost, store_path_.string());
}

void StateDirectory::save_model() noexcept {
  const auto lock = model_.lock_writes();
  const ModelPtr m = model_.get();
  if (!m || m->empty()) return;
  try {
    // Written only if the file does not already hold it (a model unchanged since it was loaded or
    // saved is not rewritten at every stop, on media that may be read-only or worn), and never over
    // a model.json installed while the daemon ran.
    if (save_model_if_ours(model_, model_path_, *m) == ModelSave::kReplacedByOther)
      spdlog::warn(
          "model: {} was replaced while gearpulsed ran; left as it is (it is loaded at the next "
          "start), so the model in use is not saved",
          model_path_.string());
  } catch (const std::exception& e) {
    try {
      spdlog::error("model: cannot save {} at shutdown: {}; {}", model_path_.string(), e.what(),
                    state_dir_advice(dir_));
    } catch (...) {
    }
  }
}

void StateDirectory::reset_model(bool keep_samples) {
  {
    // A fit running now finds the generation changed and discards its result.
    const auto lock = model_.lock_writes();
    model_.set(nullptr);
    remove_file_durable(model_path_);
    model_.set_file_stamp(std::nullopt);
  }
  if (!keep_samples) {
    store_.clear();
    // The file that cannot be replaced still holds the cleared pairs, and the next start would bring
    // them back: it goes (with its journal), or the reply says it stays.
    if (!save_store("reset-model")) {
      try {
        remove_file_durable(TrainingStore::journal_path(store_path_));
        remove_file_durable(store_path_);
      } catch (const std::exception& e) {
        throw std::runtime_error(fmt::format(
            "the model is forgotten, but the training pairs cannot be cleared from {} ({}): they come "
            "back at the next start",
            store_path_.string(), e.what()));
      }
    }
  }
}

}  // namespace gearpulse::daemon
