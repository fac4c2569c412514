#pragma once
// The bounded store of aligned (t, GPS speed, engine frequency) pairs the retrainer learns from.
// It keeps the last `max_age` seconds of driving (and at most `max_samples`), survives restarts through an
// atomically written file with a header and a checksum, and detects a torn or corrupt file.
// Between those (large, infrequent) saves, the pairs added since the last one go to a journal beside
// the file, appended in small synced writes: a power cut loses at most the pairs since the last append.
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

// The most pairs a store may be configured to keep (model.max_samples): with it, the longest training
// file and journal a daemon writes, and so the most that is read of either.
inline constexpr std::size_t kMaxStoreSamples = 50'000'000;

class TrainingStore {
 public:
  // t of stored samples is wall-clock (UNIX) seconds, so ages stay meaningful across reboots.
  TrainingStore(double max_age_s, std::size_t max_samples);

  // Appends a pair (samples must carry both speed and frequency; others are ignored) and drops what
  // falls out of the bounds. Returns false if the sample was rejected.
  bool add(const Sample& sample);
  void set_limits(double max_age_s, std::size_t max_samples);
  // Forgets every pair; the next save() removes the journal before it writes the file, so no power cut
  // brings the cleared pairs back.
  void clear();

  [[nodiscard]] std::vector<Sample> snapshot() const;
  [[nodiscard]] std::size_t size() const;
  // The most pairs the store keeps: max_samples, or max_age_s of driving at a pair a second.
  [[nodiscard]] std::size_t capacity() const;
  // Something the file at the last save() does not hold: pairs added, or a clear().
  [[nodiscard]] bool unsaved() const;
  // Pairs that neither the file of the last save() nor the journal holds: what a power cut now would lose.
  [[nodiscard]] std::size_t unkept() const;
  // Pairs added since the last mark_trained() (or since start).
  [[nodiscard]] std::size_t new_samples() const;
  void mark_trained(std::size_t consumed);
  // Clears so far: with it, mark_trained() of a count read before a clear (a fit's, with a reset during
  // the fit) leaves the pairs added since the clear new, as they are.
  [[nodiscard]] std::uint64_t clears() const;
  void mark_trained(std::size_t consumed, std::uint64_t clears_seen);
  // Counts as new the pairs later than `t` (wall-clock s): those a fit ending at `t` has not seen, kept
  // from earlier runs of the daemon.
  void set_new_after(double t);
  // Counts as new the pairs after the last one equal to `last` (store order); false, and nothing
  // changed, when no pair is.
  bool set_new_after_pair(const Sample& last);

  // File format: magic, version, record count, records, CRC-32 of all that precedes it.
  [[nodiscard]] std::string serialize() const;
  // Replaces the content; on a bad blob leaves the store empty and returns the reason (else empty). A
  // record that holds its place and the file's checksum but no plausible pair (a NaN, a negative speed)
  // is left out and counted in skipped(); the others are kept.
  std::string deserialize(std::string_view blob);
  // Records left out by the last deserialize() or load() as no plausible pair.
  [[nodiscard]] std::size_t skipped() const;
  // Atomic save (temp + fsync + rename), then a fresh journal that extends it. Throws
  // std::system_error (when the save itself fails, the previous file and journal still hold the pairs).
  void save(const std::filesystem::path& path);
  // Loads; returns the reason when the file is corrupt (the store is then empty), empty on success or
  // when the file does not exist. Throws FileRefused for a file that is not regular or is longer than a
  // store of kMaxStoreSamples pairs, std::system_error on I/O errors.
  std::string load(const std::filesystem::path& path);

  // The journal of `path` (journal_path()): magic, version, the checksum of the saved file it extends,
  // then records of one pair and its own CRC-32.
  [[nodiscard]] static std::filesystem::path journal_path(const std::filesystem::path& path);
  // Size in bytes of a saved store of `pairs` pairs.
  [[nodiscard]] static double file_bytes(std::size_t pairs) noexcept;
  // Appends the pairs added since the last save or append to the journal and syncs it (rewriting the
  // journal whole, atomically, when it is missing, stale or after a failed append). Returns how many
  // pairs were written. Throws std::system_error; the pairs are then tried again at the next call.
  std::size_t append_journal(const std::filesystem::path& path);
  struct JournalReplay {
    std::size_t recovered = 0;  // pairs added from the journal
    std::size_t skipped = 0;    // whole records (their checksum holds) that are no plausible pair
    std::string problem;        // a journal that is not one, a torn record at its end, skipped records
    bool stale = false;         // the journal extends an older save (its pairs are in the file already)
  };
  // After load(): adds the pairs of the journal if it extends the file just loaded (the pairs a power cut
  // or a crash kept from the next save). Throws FileRefused as load() does, std::system_error on I/O
  // errors.
  JournalReplay replay_journal(const std::filesystem::path& path);

 private:
  void enforce_bounds_locked();
  // Replaces the pairs with `pairs` read from a file (none of them new), `skipped` records left out.
  void install_locked(std::deque<Sample> pairs, std::size_t skipped);
  void clamp_counts_locked() noexcept;
  void empty_locked() noexcept;
  std::size_t append_journal_io(const std::filesystem::path& path);
  [[nodiscard]] std::string serialize_locked() const;

  mutable std::mutex mutex_;
  // Serialises the file writes (save, journal) of the state saver's thread, of the stop and of a reset from
  // the control thread, held across the I/O; mutex_ is taken only to copy, so add() never waits on a disk.
  std::mutex io_mutex_;
  std::deque<Sample> samples_;
  // Driving time samples_ covers: the steps between consecutive pairs, each counted up to kMaxStepS, so
  // that neither a car parked for days nor a wall clock set forward or back by years ages the pairs.
  static constexpr double kMaxStepS = 10.0;
  double span_s_ = 0.0;
  [[nodiscard]] static double step(const Sample& a, const Sample& b) noexcept;
  void push_back_locked(const Sample& s);
  void pop_front_locked() noexcept;
  double max_age_s_;
  std::size_t max_samples_;
  std::size_t new_samples_ = 0;
  std::uint64_t clears_ = 0;
  std::size_t skipped_ = 0;  // records of the last load that were no plausible pair
  // Journal bookkeeping: pairs at the back of samples_ added since the last save (all in the journal
  // when it is current), and how many of those are not yet in it.
  std::size_t since_save_ = 0;
  std::size_t unjournaled_ = 0;
  std::uint32_t saved_crc_ = 0;   // checksum of the saved file the journal extends (0: no file)
  bool journal_current_ = false;  // the journal on disk extends saved_crc_ and ends with a whole record
  bool cleared_ = false;          // clear() since the last save: the journal holds pairs meant to be gone
};

[[nodiscard]] std::uint32_t crc32(std::string_view data) noexcept;

}  // namespace gearpulse::daemon
