#include "daemon/training_store.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "daemon/atomic_file.hpp"

namespace gearpulse::daemon {
namespace {

constexpr char kMagic[8] = {'G', 'P', 'T', 'R', 'A', 'I', 'N', '\n'};
constexpr std::uint32_t kVersion = 1;
constexpr std::uint32_t kRecordSize = 3 * sizeof(double);
constexpr std::size_t kHeaderSize = sizeof kMagic + 2 * sizeof(std::uint32_t) + sizeof(std::uint64_t);

template <typename T>
void put(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

template <typename T>
T get(std::string_view in, std::size_t offset) {
  T value;
  std::memcpy(&value, in.data() + offset, sizeof(T));
  return value;
}

bool plausible(const Sample& s) {
  return std::isfinite(s.t) && std::isfinite(s.speed) && std::isfinite(s.freq) && s.speed >= 0.0 &&
         s.freq > 0.0;
}

}  // namespace

std::uint32_t crc32(std::string_view data) noexcept {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k)
        c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  std::uint32_t crc = 0xFFFFFFFFu;
  for (unsigned char byte : data)
    crc = table[(crc ^ byte) & 0xFFu] ^ (crc >> 8);
  return crc ^ 0xFFFFFFFFu;
}

TrainingStore::TrainingStore(double max_age_s, std::size_t max_samples)
    : max_age_s_(max_age_s), max_samples_(max_samples) {}

bool TrainingStore::add(const Sample& sample) {
  if (!plausible(sample)) return false;
  std::lock_guard lock(mutex_);
  samples_.push_back(sample);
  ++new_samples_;
  enforce_bounds_locked();
  return true;
}

void TrainingStore::set_limits(double max_age_s, std::size_t max_samples) {
  std::lock_guard lock(mutex_);
  max_age_s_ = max_age_s;
  max_samples_ = max_samples;
  enforce_bounds_locked();
}

void TrainingStore::prune(double now_wall_s) {
  std::lock_guard lock(mutex_);
  const double oldest = now_wall_s - max_age_s_;
  while (!samples_.empty() && samples_.front().t < oldest)
    samples_.pop_front();
  new_samples_ = std::min(new_samples_, samples_.size());
}

void TrainingStore::clear() {
  std::lock_guard lock(mutex_);
  samples_.clear();
  new_samples_ = 0;
}

std::vector<Sample> TrainingStore::snapshot() const {
  std::lock_guard lock(mutex_);
  return {samples_.begin(), samples_.end()};
}

std::size_t TrainingStore::size() const {
  std::lock_guard lock(mutex_);
  return samples_.size();
}

std::size_t TrainingStore::new_samples() const {
  std::lock_guard lock(mutex_);
  return new_samples_;
}

void TrainingStore::mark_trained(std::size_t consumed) {
  std::lock_guard lock(mutex_);
  new_samples_ -= std::min(consumed, new_samples_);
}

void TrainingStore::enforce_bounds_locked() {
  // Age is judged against the newest sample, so a wrong wall clock cannot wipe the store.
  if (!samples_.empty()) {
    const double oldest = samples_.back().t - max_age_s_;
    while (!samples_.empty() && samples_.front().t < oldest)
      samples_.pop_front();
  }
  while (samples_.size() > max_samples_)
    samples_.pop_front();
  new_samples_ = std::min(new_samples_, samples_.size());
}

std::string TrainingStore::serialize() const {
  std::lock_guard lock(mutex_);
  std::string out;
  out.reserve(kHeaderSize + samples_.size() * kRecordSize + sizeof(std::uint32_t));
  out.append(kMagic, sizeof kMagic);
  put(out, kVersion);
  put(out, kRecordSize);
  put(out, static_cast<std::uint64_t>(samples_.size()));
  for (const Sample& s : samples_) {
    put(out, s.t);
    put(out, s.speed);
    put(out, s.freq);
  }
  put(out, crc32(out));
  return out;
}

std::string TrainingStore::deserialize(std::string_view blob) {
  clear();
  if (blob.size() < kHeaderSize + sizeof(std::uint32_t))
    return "file too short (" + std::to_string(blob.size()) + " bytes)";
  if (std::memcmp(blob.data(), kMagic, sizeof kMagic) != 0) return "not a training store (bad magic)";
  const auto version = get<std::uint32_t>(blob, sizeof kMagic);
  if (version != kVersion) return "unsupported version " + std::to_string(version);
  const auto record = get<std::uint32_t>(blob, sizeof kMagic + 4);
  if (record != kRecordSize) return "unexpected record size " + std::to_string(record);
  const auto count = get<std::uint64_t>(blob, sizeof kMagic + 8);
  const std::size_t body = blob.size() - kHeaderSize - sizeof(std::uint32_t);
  if (count > body / kRecordSize || count * kRecordSize != body)
    return "truncated or padded: header says " + std::to_string(count) + " records, file holds " +
           std::to_string(body) + " bytes";
  const std::size_t crc_at = blob.size() - sizeof(std::uint32_t);
  if (get<std::uint32_t>(blob, crc_at) != crc32(blob.substr(0, crc_at))) return "checksum mismatch";
  std::deque<Sample> loaded;
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t at = kHeaderSize + i * kRecordSize;
    Sample s{get<double>(blob, at), get<double>(blob, at + 8), get<double>(blob, at + 16)};
    if (!plausible(s)) return "implausible record " + std::to_string(i);
    loaded.push_back(s);
  }
  std::lock_guard lock(mutex_);
  samples_ = std::move(loaded);
  new_samples_ = 0;
  enforce_bounds_locked();
  return {};
}

void TrainingStore::save(const std::filesystem::path& path) const {
  write_file_atomic(path, serialize());
}

std::string TrainingStore::load(const std::filesystem::path& path) {
  const auto blob = read_file(path);
  if (!blob) {
    clear();
    return {};
  }
  return deserialize(*blob);
}

}  // namespace gearpulse::daemon
