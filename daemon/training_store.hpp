#pragma once
// The bounded store of aligned (t, GPS speed, engine frequency) pairs the retrainer learns from.
// It keeps the last `max_age` seconds (and at most `max_samples`), survives restarts through an
// atomically written file with a header and a checksum, and detects a torn or corrupt file.
#include <cstddef>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "core/sample.hpp"

namespace gearpulse::daemon {

class TrainingStore {
 public:
  // t of stored samples is wall-clock (UNIX) seconds, so ages stay meaningful across reboots.
  TrainingStore(double max_age_s, std::size_t max_samples);

  // Appends a pair (samples must carry both speed and frequency; others are ignored) and drops what
  // falls out of the bounds. Returns false if the sample was rejected.
  bool add(const Sample& sample);
  void set_limits(double max_age_s, std::size_t max_samples);
  // Drops samples older than now - max_age.
  void prune(double now_wall_s);
  void clear();

  [[nodiscard]] std::vector<Sample> snapshot() const;
  [[nodiscard]] std::size_t size() const;
  // Pairs added since the last mark_trained() (or since start).
  [[nodiscard]] std::size_t new_samples() const;
  void mark_trained(std::size_t consumed);

  // File format: magic, version, record count, records, CRC-32 of all that precedes it.
  [[nodiscard]] std::string serialize() const;
  // Replaces the content; on a bad blob leaves the store empty and returns the reason (else empty).
  std::string deserialize(std::string_view blob);
  // Atomic save (temp + fsync + rename). Throws std::system_error.
  void save(const std::filesystem::path& path) const;
  // Loads; returns the reason when the file is corrupt (the store is then empty), empty on success or
  // when the file does not exist. Throws std::system_error on I/O errors.
  std::string load(const std::filesystem::path& path);

 private:
  void enforce_bounds_locked();

  mutable std::mutex mutex_;
  std::deque<Sample> samples_;
  double max_age_s_;
  std::size_t max_samples_;
  std::size_t new_samples_ = 0;
};

[[nodiscard]] std::uint32_t crc32(std::string_view data) noexcept;

}  // namespace gearpulse::daemon
