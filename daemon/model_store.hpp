#pragma once
// The current gear model: immutable, swapped whole and atomically, persisted as state_dir/model.json in
// the format of `gearpulse fit --out`.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "core/gear_model.hpp"

namespace gearpulse::daemon {

using ModelPtr = std::shared_ptr<const GearModel>;

// What identifies one version of a file: a file replaced (renamed over, rewritten) gets another.
struct FileStamp {
  std::uint64_t device = 0, inode = 0, size = 0;
  std::int64_t mtime_ns = 0;
  bool operator==(const FileStamp&) const = default;
};
// The stamp of the file at `path`, or none when there is no file.
[[nodiscard]] std::optional<FileStamp> stamp_of(const std::filesystem::path& path) noexcept;

// The model is held under a mutex held only to copy or swap the pointer, not in a
// std::atomic<std::shared_ptr>: libstdc++ 12's load() releases that type's internal lock with a relaxed
// store, so a reader's read of the pointer is not ordered before the next store's write (ThreadSanitizer
// reports it; on a weakly ordered CPU the reader could pair the new pointer with the old reference count).
class ModelHolder {
 public:
  [[nodiscard]] ModelPtr get() const noexcept {
    const std::lock_guard lock(model_mutex_);
    return model_;
  }
  // Every set() starts a new generation. A writer that read the generation before long work (a fit)
  // installs its result only if it is unchanged, so a fit begun before a reset-model cannot bring the
  // forgotten model back.
  void set(ModelPtr model) noexcept {
    {
      const std::lock_guard lock(model_mutex_);
      model_.swap(model);
      generation_.fetch_add(1, std::memory_order_acq_rel);
    }
    // The model replaced (in `model`) is released here, outside the lock.
  }
  [[nodiscard]] std::uint64_t generation() const noexcept {
    return generation_.load(std::memory_order_acquire);
  }
  // Writers (a retrain, a reset) hold this while they check the generation, change the model and its
  // file, so that a save and a removal of model.json never interleave.
  [[nodiscard]] std::unique_lock<std::mutex> lock_writes() { return std::unique_lock(write_mutex_); }
  [[nodiscard]] bool trained() const noexcept {
    const ModelPtr m = get();
    return m && !m->empty();
  }
  // The version of model.json this daemon last loaded or wrote (none: it has neither, or removed it).
  // Read and set under lock_writes().
  [[nodiscard]] const std::optional<FileStamp>& file_stamp() const noexcept { return file_stamp_; }
  void set_file_stamp(std::optional<FileStamp> stamp) noexcept { file_stamp_ = stamp; }

 private:
  std::optional<FileStamp> file_stamp_;
  mutable std::mutex model_mutex_;
  ModelPtr model_;
  std::atomic<std::uint64_t> generation_{0};
  std::mutex write_mutex_;
};

// The longest model.json read: a model of the most gears with its statistics is a few kB, and parsing
// JSON takes many times its size in memory (a 20 MB file took the daemon to 453 MB).
inline constexpr std::size_t kMaxModelBytes = std::size_t{1} << 20;

struct ModelLoad {
  ModelPtr model;     // null when absent or rejected
  std::string error;  // why a present file was rejected, for its content or because it cannot be read
};

// Reads `path`; a missing file gives {null, ""}; a corrupt or unreadable one, or one that is not a regular
// file or is longer than kMaxModelBytes, {null, reason}. Never throws.
[[nodiscard]] ModelLoad load_model_file(const std::filesystem::path& path) noexcept;
// Atomic write. Throws std::system_error.
void save_model_file(const std::filesystem::path& path, const GearModel& model);
// True when the file at `path` holds `model`: what save_model_file would write for it, whatever the
// spacing and key order of the file (a model written by `gearpulse fit --out`, or by an earlier version).
[[nodiscard]] bool model_file_holds(const std::filesystem::path& path, const GearModel& model) noexcept;

enum class ModelSave { kSaved, kAlreadyThere, kReplacedByOther };
// Saves `model` to `path` for the daemon whose model `holder` keeps (under holder.lock_writes()), unless a
// file is there that the daemon neither loaded nor wrote: a model.json installed while it ran (a user's
// `gearpulse fit --out`) is not overwritten; it is loaded at the next start. Throws std::system_error.
ModelSave save_model_if_ours(ModelHolder& holder, const std::filesystem::path& path, const GearModel& model);

}  // namespace gearpulse::daemon
