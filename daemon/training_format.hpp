#pragma once
// The bytes of training.bin and its journal (TrainingStore writes and reads them): the layout, one pair's
// record, the checksum, and the readers that take either file in pieces as it is read, keeping only the
// newest pairs a store may hold.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <deque>
#include <string>
#include <string_view>
#include <vector>

#include "core/sample.hpp"

namespace gearpulse::daemon::training_format {

inline constexpr char kMagic[8] = {'G', 'P', 'T', 'R', 'A', 'I', 'N', '\n'};
inline constexpr std::uint32_t kVersion = 1;
inline constexpr std::uint32_t kRecordSize = 3 * sizeof(double);
inline constexpr std::size_t kHeaderSize = sizeof kMagic + 2 * sizeof(std::uint32_t) + sizeof(std::uint64_t);
inline constexpr char kJournalMagic[8] = {'G', 'P', 'J', 'O', 'U', 'R', 'N', '\n'};
inline constexpr std::size_t kJournalHeaderSize = sizeof kJournalMagic + 2 * sizeof(std::uint32_t);
inline constexpr std::size_t kJournalRecordSize = kRecordSize + sizeof(std::uint32_t);

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

// The checksum a saved store ends with (what a journal names as the file it extends); 0 for none.
inline std::uint32_t trailing_crc(std::string_view blob) {
  return blob.size() >= sizeof(std::uint32_t) ? get<std::uint32_t>(blob, blob.size() - sizeof(std::uint32_t))
                                              : 0;
}

inline void put_record(std::string& out, const Sample& s) {
  put(out, s.t);
  put(out, s.speed);
  put(out, s.freq);
}

inline Sample get_record(std::string_view in, std::size_t offset) {
  return {get<double>(in, offset), get<double>(in, offset + 8), get<double>(in, offset + 16)};
}

inline bool plausible(const Sample& s) {
  return std::isfinite(s.t) && std::isfinite(s.speed) && std::isfinite(s.freq) && s.speed >= 0.0 &&
         s.freq > 0.0;
}

// CRC-32 (IEEE 802.3) of `data` continued from `crc`: crc32() starts from all ones and inverts the end.
[[nodiscard]] std::uint32_t crc32_update(std::uint32_t crc, std::string_view data) noexcept;

// The newest `keep` pairs of those added, in a ring that grows to `keep` and then overwrites its oldest:
// no allocation per pair once full (a deque's push and pop allocated and freed a block every 21 pairs).
class NewestPairs {
 public:
  explicit NewestPairs(std::size_t keep) : keep_(keep) {}
  void add(const Sample& s);
  // The pairs kept, oldest first.
  [[nodiscard]] std::deque<Sample> in_order() const;

 private:
  std::size_t keep_;
  std::vector<Sample> ring_;
  std::size_t oldest_ = 0;  // ring_'s oldest pair once it holds `keep`
};

// A saved store read piece by piece as load() reads the file: only the newest `keep` plausible pairs are
// kept, so a file written under a larger model.max_samples costs no more memory than the store it is
// loaded into (pruned as a store of all its pairs would be: the newest `keep`, then by age).
class StoreReader {
 public:
  explicit StoreReader(std::size_t keep) : pairs(keep) {}

  void feed(std::string_view bytes);

  // Why the bytes fed are no store, "" when they are one.
  [[nodiscard]] std::string finish() const;
  [[nodiscard]] std::uint32_t stored_crc() const { return trailing_crc(pending_); }

  NewestPairs pairs;        // the newest `keep` plausible pairs
  std::size_t skipped = 0;  // records that are no plausible pair

 private:
  // Moves bytes from the front of `bytes` to pending_ until it holds `size`.
  void fill(std::string_view& bytes, std::size_t size, bool checksummed);
  [[nodiscard]] std::string check_header();
  void take(const Sample& s);

  std::uint64_t total_ = 0;  // bytes fed
  std::string pending_;      // the header, a record split between pieces, or the trailing checksum
  bool header_read_ = false;
  std::string header_problem_;
  std::uint64_t count_ = 0;    // records the header announces
  std::uint64_t records_ = 0;  // records read
  std::uint32_t crc_ = 0xFFFFFFFFu;
};

// A journal read piece by piece as replay_journal() reads it, keeping the newest `keep` plausible pairs.
// Records are read up to the first that fails its own checksum (a torn append at a power cut).
class JournalReader {
 public:
  explicit JournalReader(std::size_t keep) : pairs(keep) {}

  void feed(std::string_view bytes);

  // Why the journal is none (its header), "" when it is one.
  [[nodiscard]] std::string header_problem() const;
  // The checksum of the saved store the journal extends.
  [[nodiscard]] std::uint32_t extends() const;
  // What was left unread past the last whole record, "" for nothing.
  [[nodiscard]] std::string tail_problem() const;

  NewestPairs pairs;  // the newest `keep` plausible pairs recovered
  std::size_t recovered = 0;
  std::size_t skipped = 0;
  std::size_t first_skipped = 0;  // 1-based number of the first record skipped

 private:
  std::uint64_t total_ = 0;
  std::string header_;
  std::string pending_;  // a record split between pieces
  std::uint64_t records_ = 0;
  bool broken_ = false;
};

}  // namespace gearpulse::daemon::training_format
