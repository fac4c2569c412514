#pragma once
// The current gear model: immutable, swapped whole and atomically, persisted as state_dir/model.json in
// the format of `gearpulse fit --out`.
#include <atomic>
#include <filesystem>
#include <memory>
#include <string>

#include "core/gear_model.hpp"

namespace gearpulse::daemon {

using ModelPtr = std::shared_ptr<const GearModel>;

class ModelHolder {
 public:
  [[nodiscard]] ModelPtr get() const noexcept { return model_.load(std::memory_order_acquire); }
  void set(ModelPtr model) noexcept { model_.store(std::move(model), std::memory_order_release); }
  [[nodiscard]] bool trained() const noexcept {
    const ModelPtr m = get();
    return m && !m->empty();
  }

 private:
  std::atomic<ModelPtr> model_;
};

struct ModelLoad {
  ModelPtr model;     // null when absent or rejected
  std::string error;  // why a present file was rejected (empty otherwise)
};

// Reads `path`; a missing file gives {null, ""}; a corrupt one gives {null, reason}. Never throws.
[[nodiscard]] ModelLoad load_model_file(const std::filesystem::path& path) noexcept;
// Atomic write. Throws std::system_error.
void save_model_file(const std::filesystem::path& path, const GearModel& model);

}  // namespace gearpulse::daemon
