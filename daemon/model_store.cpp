#include "daemon/model_store.hpp"

#include "daemon/atomic_file.hpp"

namespace gearpulse::daemon {

ModelLoad load_model_file(const std::filesystem::path& path) noexcept {
  try {
    const auto text = read_file(path);
    if (!text) return {};
    GearModel model = parse_model(*text);
    return {std::make_shared<const GearModel>(std::move(model)), {}};
  } catch (const std::exception& e) {
    return {nullptr, e.what()};
  }
}

void save_model_file(const std::filesystem::path& path, const GearModel& model) {
  write_file_atomic(path, serialize_model(model) + "\n");
}

}  // namespace gearpulse::daemon
