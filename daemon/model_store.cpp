#include "daemon/model_store.hpp"

#include <optional>

#include "daemon/atomic_file.hpp"

namespace gearpulse::daemon {

ModelLoad load_model_file(const std::filesystem::path& path) noexcept {
  std::optional<std::string> text;
  try {
    text = read_file(path);
  } catch (const std::exception& e) {
    return {nullptr, e.what(), true};
  }
  if (!text) return {};
  try {
    GearModel model = parse_model(*text);
    return {std::make_shared<const GearModel>(std::move(model)), {}};
  } catch (const std::exception& e) {
    return {nullptr, e.what()};
  }
}

void save_model_file(const std::filesystem::path& path, const GearModel& model) {
  write_file_atomic(path, serialize_model(model) + "\n");
}

bool model_file_holds(const std::filesystem::path& path, const GearModel& model) noexcept {
  try {
    const std::optional<std::string> text = read_file(path);
    return text && *text == serialize_model(model) + "\n";
  } catch (const std::exception&) {
    return false;
  }
}

}  // namespace gearpulse::daemon
