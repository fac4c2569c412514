#pragma once
// The current gear model: immutable, swapped whole and atomically, persisted as state_dir/model.json in
// the format of `gearpulse fit --out`.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>

#include "core/gear_model.hpp"

namespace gearpulse::daemon {

using ModelPtr = std::shared_ptr<const GearModel>;

class ModelHolder {
 public:
  [[nodiscard]] ModelPtr get() const noexcept { return model_.load(std::memory_order_acquire); }
  // Every set() starts a new generation. A writer that read the generation before long work (a fit)
  // installs its result only if it is unchanged, so a fit begun before a reset-model cannot bring the
  // forgotten model back.
  void set(ModelPtr model) noexcept {
    model_.store(std::move(model), std::memory_order_release);
    generation_.fetch_add(1, std::memory_order_acq_rel);
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

 private:
  std::atomic<ModelPtr> model_;
  std::atomic<std::uint64_t> generation_{0};
  std::mutex write_mutex_;
};

struct ModelLoad {
  ModelPtr model;           // null when absent or rejected
  std::string error;        // why a present file was rejected (empty otherwise)
  bool unreadable = false;  // ... because it could not be read (permissions, I/O), not for its content
};

// Reads `path`; a missing file gives {null, ""}; a corrupt one gives {null, reason}. Never throws.
[[nodiscard]] ModelLoad load_model_file(const std::filesystem::path& path) noexcept;
// Atomic write. Throws std::system_error.
void save_model_file(const std::filesystem::path& path, const GearModel& model);
// True when the file at `path` holds exactly what save_model_file would write for `model`.
[[nodiscard]] bool model_file_holds(const std::filesystem::path& path, const GearModel& model) noexcept;

}  // namespace gearpulse::daemon
