#include "daemon/training_store.hpp"

#include <algorithm>
#include <cmath>
#include <exception>

#include "common/atomic_file.hpp"
#include "daemon/training_format.hpp"

namespace gearpulse::daemon {

// The file layout (training_format.hpp); named, not imported: this file shares a unity batch with others.
namespace tf = training_format;

std::uint32_t crc32(std::string_view data) noexcept {
  return tf::crc32_update(0xFFFFFFFFu, data) ^ 0xFFFFFFFFu;
}

TrainingStore::TrainingStore(double max_age_s, std::size_t max_samples)
    : max_age_s_(max_age_s), max_samples_(max_samples) {}

double TrainingStore::step(const Sample& a, const Sample& b) noexcept {
  return std::min(std::abs(b.t - a.t), kMaxStepS);
}

void TrainingStore::push_back_locked(const Sample& s) {
  if (!samples_.empty()) span_s_ += step(samples_.back(), s);
  samples_.push_back(s);
}

void TrainingStore::pop_front_locked() noexcept {
  if (samples_.size() >= 2) span_s_ -= step(samples_[0], samples_[1]);
  samples_.pop_front();
  if (samples_.size() <= 1) span_s_ = 0.0;
}

bool TrainingStore::add(const Sample& sample) {
  if (!tf::plausible(sample)) return false;
  std::lock_guard lock(mutex_);
  push_back_locked(sample);
  ++new_samples_;
  ++since_save_;
  ++unjournaled_;
  enforce_bounds_locked();
  return true;
}

void TrainingStore::set_limits(double max_age_s, std::size_t max_samples) {
  std::lock_guard lock(mutex_);
  max_age_s_ = max_age_s;
  max_samples_ = max_samples;
  enforce_bounds_locked();
}

std::size_t TrainingStore::capacity() const {
  std::lock_guard lock(mutex_);
  return std::min(max_samples_, static_cast<std::size_t>(std::max(1.0, std::floor(max_age_s_))));
}

void TrainingStore::clear() {
  std::lock_guard lock(mutex_);
  empty_locked();
  cleared_ = true;
  ++clears_;
}

void TrainingStore::empty_locked() noexcept {
  samples_.clear();
  span_s_ = 0.0;
  new_samples_ = since_save_ = unjournaled_ = skipped_ = 0;
}

std::vector<Sample> TrainingStore::snapshot() const {
  std::lock_guard lock(mutex_);
  return {samples_.begin(), samples_.end()};
}

std::size_t TrainingStore::size() const {
  std::lock_guard lock(mutex_);
  return samples_.size();
}

std::size_t TrainingStore::unkept() const {
  std::lock_guard lock(mutex_);
  // A journal that is not current is rewritten whole at the next append: count every pair since the save.
  return journal_current_ ? unjournaled_ : since_save_;
}

bool TrainingStore::unsaved() const {
  std::lock_guard lock(mutex_);
  return since_save_ > 0 || cleared_;
}

std::size_t TrainingStore::new_samples() const {
  std::lock_guard lock(mutex_);
  return new_samples_;
}

void TrainingStore::mark_trained(std::size_t consumed) {
  std::lock_guard lock(mutex_);
  new_samples_ -= std::min(consumed, new_samples_);
}

std::uint64_t TrainingStore::clears() const {
  std::lock_guard lock(mutex_);
  return clears_;
}

void TrainingStore::mark_trained(std::size_t consumed, std::uint64_t clears_seen) {
  std::lock_guard lock(mutex_);
  if (clears_ == clears_seen) new_samples_ -= std::min(consumed, new_samples_);
}

bool TrainingStore::set_new_after_pair(const Sample& last) {
  std::lock_guard lock(mutex_);
  for (std::size_t i = samples_.size(); i-- > 0;) {
    const Sample& s = samples_[i];
    if (s.t == last.t && s.speed == last.speed && s.freq == last.freq) {
      new_samples_ = samples_.size() - i - 1;
      return true;
    }
  }
  return false;
}

void TrainingStore::set_new_after(double t) {
  std::lock_guard lock(mutex_);
  new_samples_ = static_cast<std::size_t>(
      std::count_if(samples_.begin(), samples_.end(), [t](const Sample& s) { return s.t > t; }));
}

void TrainingStore::enforce_bounds_locked() {
  // Age is the driving time since a pair, not the wall clock's: pairs older than max_age of driving fall
  // off the front. (Judged against the newest pair's time, a weekend parked or a clock set forward
  // emptied the store at the first new pair, and a pair stamped in the future stopped all pruning.)
  while (samples_.size() > 1 && span_s_ > max_age_s_)
    pop_front_locked();
  while (samples_.size() > max_samples_)
    pop_front_locked();
  clamp_counts_locked();
}

// Counts of pairs at the back of samples_ cannot exceed what is left after pairs fell off the front.
void TrainingStore::clamp_counts_locked() noexcept {
  new_samples_ = std::min(new_samples_, samples_.size());
  since_save_ = std::min(since_save_, samples_.size());
  unjournaled_ = std::min(unjournaled_, samples_.size());
}

std::size_t TrainingStore::skipped() const {
  std::lock_guard lock(mutex_);
  return skipped_;
}

std::string TrainingStore::serialize() const {
  std::lock_guard lock(mutex_);
  return serialize_locked();
}

std::string TrainingStore::serialize_locked() const {
  std::string out;
  out.reserve(tf::kHeaderSize + samples_.size() * tf::kRecordSize + sizeof(std::uint32_t));
  out.append(tf::kMagic, sizeof tf::kMagic);
  tf::put(out, tf::kVersion);
  tf::put(out, tf::kRecordSize);
  tf::put(out, static_cast<std::uint64_t>(samples_.size()));
  for (const Sample& s : samples_)
    tf::put_record(out, s);
  tf::put(out, crc32(out));
  return out;
}

std::string TrainingStore::deserialize(std::string_view blob) {
  std::size_t keep = 0;
  {
    std::lock_guard lock(mutex_);
    empty_locked();
    keep = max_samples_;
  }
  tf::StoreReader reader(keep);
  reader.feed(blob);
  std::string problem = reader.finish();
  if (problem.empty()) {
    std::lock_guard lock(mutex_);
    install_locked(reader.pairs.in_order(), reader.skipped);
  }
  return problem;
}

void TrainingStore::install_locked(std::deque<Sample> pairs, std::size_t skipped) {
  skipped_ = skipped;
  samples_ = std::move(pairs);
  span_s_ = 0.0;
  for (std::size_t i = 1; i < samples_.size(); ++i)
    span_s_ += step(samples_[i - 1], samples_[i]);
  new_samples_ = 0;
  enforce_bounds_locked();
}

void TrainingStore::save(const std::filesystem::path& path) {
  std::lock_guard io(io_mutex_);
  std::string blob;
  std::size_t saved = 0, unjournaled = 0;
  bool cleared = false;
  std::exception_ptr unsynced;
  {
    // What the blob holds needs no journal; pairs added from here on do.
    std::lock_guard lock(mutex_);
    blob = serialize_locked();
    saved = since_save_;
    unjournaled = unjournaled_;
    cleared = cleared_;
    since_save_ = unjournaled_ = 0;
    cleared_ = false;
  }
  try {
    // After a clear() the old journal goes first: an empty store's file is the same bytes every time, so
    // a journal naming an earlier empty file would otherwise bring back pairs cleared since.
    if (cleared) {
      remove_file_durable(journal_path(path));
      std::lock_guard lock(mutex_);
      journal_current_ = false;
    }
    try {
      write_file_atomic(path, blob);
    } catch (const DirectorySyncError&) {
      // The new file is the one in place: the bookkeeping is that of a save (a journal from now on must
      // name it), and the error is still said once it is done (the caller tries again).
      unsynced = std::current_exception();
    }
  } catch (...) {
    // The previous file stands, and so does its journal unless it was removed (then it is rewritten
    // whole); the pairs are still to be saved (and journaled).
    std::lock_guard lock(mutex_);
    since_save_ = std::min(since_save_ + saved, samples_.size());
    unjournaled_ = std::min(unjournaled_ + unjournaled, samples_.size());
    cleared_ = cleared_ || cleared;
    throw;
  }
  {
    std::lock_guard lock(mutex_);
    saved_crc_ = tf::trailing_crc(blob);
    journal_current_ = false;
    unjournaled_ = since_save_;
  }
  // The old journal names the old file and would be ignored; a fresh one is started now rather than at
  // the next append. If this fails, the next append tries again.
  try {
    append_journal_io(path);
  } catch (const std::exception&) {
  }
  if (unsynced) std::rethrow_exception(unsynced);
}

std::string TrainingStore::load(const std::filesystem::path& path) {
  std::size_t keep = 0;
  {
    std::lock_guard lock(mutex_);
    saved_crc_ = 0;
    journal_current_ = false;
    keep = max_samples_;
  }
  tf::StoreReader reader(keep);
  const bool exists = read_file_chunks(path, static_cast<std::size_t>(file_bytes(kMaxStoreSamples)),
                                       [&reader](std::string_view piece) { reader.feed(piece); });
  const std::string problem = exists ? reader.finish() : std::string();
  std::lock_guard lock(mutex_);
  empty_locked();
  // A journal extends a file that loaded; one written after a corrupt file (set aside by the caller)
  // extends none, as does one of a first run that never saved.
  if (exists && problem.empty()) {
    install_locked(reader.pairs.in_order(), reader.skipped);
    saved_crc_ = reader.stored_crc();
  }
  return problem;
}

double TrainingStore::file_bytes(std::size_t pairs) noexcept {
  return static_cast<double>(tf::kHeaderSize + sizeof(std::uint32_t)) +
         static_cast<double>(pairs) * static_cast<double>(tf::kRecordSize);
}

std::filesystem::path TrainingStore::journal_path(const std::filesystem::path& path) {
  std::filesystem::path journal = path;
  journal += ".journal";
  return journal;
}

std::size_t TrainingStore::append_journal(const std::filesystem::path& path) {
  std::lock_guard io(io_mutex_);
  return append_journal_io(path);
}

std::size_t TrainingStore::append_journal_io(const std::filesystem::path& path) {
  std::string out;
  std::size_t count = 0;
  bool rewrite = false;
  {
    std::lock_guard lock(mutex_);
    rewrite = !journal_current_;
    count = rewrite ? since_save_ : unjournaled_;
    if (!rewrite && count == 0) return 0;
    if (rewrite) {
      out.append(tf::kJournalMagic, sizeof tf::kJournalMagic);
      tf::put(out, tf::kVersion);
      tf::put(out, saved_crc_);
    }
    for (auto it = samples_.end() - static_cast<std::ptrdiff_t>(count); it != samples_.end(); ++it) {
      const std::size_t at = out.size();
      tf::put_record(out, *it);
      tf::put(out, crc32(std::string_view(out).substr(at)));
    }
    unjournaled_ = 0;
    journal_current_ = true;
  }
  try {
    if (rewrite)
      write_file_atomic(journal_path(path), out);
    else
      append_file_durable(journal_path(path), out);
  } catch (...) {
    // A failed append may have left part of a record: the journal is rewritten whole next time.
    std::lock_guard lock(mutex_);
    journal_current_ = false;
    unjournaled_ = since_save_;
    throw;
  }
  return count;
}

TrainingStore::JournalReplay TrainingStore::replay_journal(const std::filesystem::path& path) {
  JournalReplay replay;
  std::size_t keep = 0;
  {
    std::lock_guard lock(mutex_);
    keep = max_samples_;
  }
  // A journal holds at most the pairs since the last save, never more than the store does.
  tf::JournalReader reader(keep);
  if (!read_file_chunks(journal_path(path),
                        tf::kJournalHeaderSize + kMaxStoreSamples * tf::kJournalRecordSize,
                        [&reader](std::string_view piece) { reader.feed(piece); }))
    return replay;
  if (replay.problem = reader.header_problem(); !replay.problem.empty()) return replay;
  std::lock_guard lock(mutex_);
  // A journal names the saved file it follows: one that follows another file holds pairs that file
  // already has. But with no pairs loaded (that file lost or set aside as corrupt) its pairs are in no
  // other place, and are kept.
  if (reader.extends() != saved_crc_ && !samples_.empty()) {
    replay.stale = true;
    return replay;
  }
  for (const Sample& s : reader.pairs.in_order())
    push_back_locked(s);
  replay.recovered = reader.recovered;
  replay.skipped = reader.skipped;
  if (replay.skipped > 0)
    replay.problem = std::to_string(replay.skipped) + " record(s) from record " +
                     std::to_string(reader.first_skipped) +
                     " on hold their checksum but no plausible pair (skipped)";
  if (const std::string tail = reader.tail_problem(); !tail.empty())
    replay.problem += (replay.problem.empty() ? "" : "; ") + tail;
  // The recovered pairs are in no saved file: they count as added since the save, and the journal is
  // rewritten with them (past any torn end) at the next append.
  new_samples_ += replay.recovered;
  since_save_ += replay.recovered;
  unjournaled_ = since_save_;
  journal_current_ = false;
  enforce_bounds_locked();
  return replay;
}

}  // namespace gearpulse::daemon
