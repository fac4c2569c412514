#include "daemon/model_store.hpp"

#include <sys/stat.h>

#include <optional>

#include "common/atomic_file.hpp"

namespace gearpulse::daemon {

ModelLoad load_model_file(const std::filesystem::path& path) noexcept {
  std::optional<std::string> text;
  try {
    text = read_file(path, kMaxModelBytes);
  } catch (const std::exception& e) {
    return {nullptr, e.what()};
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
  write_file_atomic(path, serialize_model(model));  // the bytes `gearpulse fit --out` writes
}

// Judged by what the file says, not by its bytes: a model written by `gearpulse fit --out` or by an earlier
// version (other spacing, other key order) is not rewritten for that alone.
bool model_file_holds(const std::filesystem::path& path, const GearModel& model) noexcept {
  try {
    const std::optional<std::string> text = read_file(path, kMaxModelBytes);
    return text && serialize_model(parse_model(*text)) == serialize_model(model);
  } catch (const std::exception&) {
    return false;
  }
}

std::optional<FileStamp> stamp_of(const std::filesystem::path& path) noexcept {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return std::nullopt;
  return FileStamp{static_cast<std::uint64_t>(st.st_dev), static_cast<std::uint64_t>(st.st_ino),
                   static_cast<std::uint64_t>(st.st_size),
                   static_cast<std::int64_t>(st.st_mtim.tv_sec) * 1'000'000'000 + st.st_mtim.tv_nsec};
}

ModelSave save_model_if_ours(ModelHolder& holder, const std::filesystem::path& path, const GearModel& model) {
  const std::optional<FileStamp> now = stamp_of(path);
  if (now && now != holder.file_stamp()) return ModelSave::kReplacedByOther;
  if (now && model_file_holds(path, model)) return ModelSave::kAlreadyThere;
  try {
    save_model_file(path, model);
  } catch (const DirectorySyncError&) {
    holder.set_file_stamp(stamp_of(path));  // it is ours, in place if not yet durable
    throw;
  }
  holder.set_file_stamp(stamp_of(path));
  return ModelSave::kSaved;
}

}  // namespace gearpulse::daemon
