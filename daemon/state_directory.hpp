#pragma once
// The state directory (model.state_dir): its lock, model.json, training.bin and the journal of pairs
// learned since the store's last save, and the problems found with them, which status lists. Loaded at
// start; saved periodically, at stop and by reset-model (docs/architecture.md, "State and persistence").
#include <cstddef>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "common/atomic_file.hpp"
#include "daemon/log_limiter.hpp"
#include "daemon/model_store.hpp"
#include "daemon/training_store.hpp"

namespace gearpulse::daemon {

// What to check when the state directory cannot be made or written, for the log line that says so: the
// setting, and the one directory the systemd unit lets the daemon write.
[[nodiscard]] std::string state_dir_advice(const std::filesystem::path& dir);

class StateDirectory {
 public:
  // `max_samples` (model.max_samples at start) sizes the room a full training store needs.
  StateDirectory(std::filesystem::path dir, ModelHolder& model, TrainingStore& store,
                 std::size_t max_samples);
  StateDirectory(const StateDirectory&) = delete;
  StateDirectory& operator=(const StateDirectory&) = delete;

  // Creates and locks the directory, says at once whether it can be written, and loads model.json,
  // training.bin and the journal (a file that will not load is set aside). False when another gearpulsed
  // keeps its state there.
  [[nodiscard]] bool load();

  bool save_store(const char* why) noexcept;  // false when it failed (logged, and in problems())
  void journal_store() noexcept;
  // At stop: a store that cannot be saved (disk full) may still take the few records of a journal append;
  // what neither takes is lost, and said so. A store the file already holds is not written again (a full
  // one is 24 MB, on flash that wears).
  void save_or_journal() noexcept;
  // At stop: the model, unless the file holds it already or was replaced while the daemon ran.
  void save_model() noexcept;
  // Forgets the model (and, unless `keep_samples`, the training pairs) in memory and on disk. Throws
  // std::runtime_error saying what could not be removed.
  void reset_model(bool keep_samples);

  // What status lists: files set aside or refused at start, and the saves and journal appends failing
  // now.
  [[nodiscard]] std::vector<std::string> problems() const;

  [[nodiscard]] const std::filesystem::path& path() const noexcept { return dir_; }
  [[nodiscard]] const std::filesystem::path& model_path() const noexcept { return model_path_; }
  [[nodiscard]] const std::filesystem::path& store_path() const noexcept { return store_path_; }

 private:
  static constexpr int kMaxSetAside = 100;  // copies of a file kept as NAME.corrupt[.N]
  void note_problem(std::string text);
  [[nodiscard]] std::string set_aside(const std::filesystem::path& path);
  void probe_writes();
  void load_model();
  void load_store();
  void recover_journal() noexcept;
  void mark_new_pairs();

  std::filesystem::path dir_;
  std::filesystem::path model_path_;
  std::filesystem::path store_path_;
  ModelHolder& model_;
  TrainingStore& store_;
  std::size_t max_samples_;
  std::optional<DirectoryLock> lock_;

  mutable std::mutex mutex_;  // the problems below: written by the main, state saver and control threads
  std::vector<std::string> problems_;
  FaultSpell save_fault_;     // the training store's saves failing (the last one's error)
  FaultSpell journal_fault_;  // journal appends failing (said once per spell)
};

}  // namespace gearpulse::daemon
